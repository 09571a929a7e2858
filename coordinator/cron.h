// Cron schedules for recurring jobs (`schedule:` in a pipeline): five fields, minute hour
// day-of-month month day-of-week, each '*', a number, a range 'a-b', a step '*/n' or 'a-b/n', or a
// comma list of those; also @hourly, @daily (@midnight), @weekly, @monthly, @yearly (@annually).
// Day of week 0-7 (0 and 7 are Sunday). As in Vixie cron, when both day fields are restricted a day
// matches either. Times are UTC.
#pragma once

#include <bitset>
#include <cstdint>
#include <string>

#include "motionpipe/base/status.h"

namespace motionpipe::coordinator {

struct CronSpec {
  std::bitset<60> minutes;
  std::bitset<24> hours;
  std::bitset<32> days;     // 1..31
  std::bitset<13> months;   // 1..12
  std::bitset<7> weekdays;  // 0..6, Sunday = 0
  bool day_restricted = false, weekday_restricted = false;
};

Result<CronSpec> ParseCron(const std::string& text);
// The first fire time strictly after `after_unix` (seconds, UTC), at a whole minute; -1 if none
// within 5 years (e.g. "0 0 31 2 *").
int64_t NextFireTime(const CronSpec& spec, int64_t after_unix);

}  // namespace motionpipe::coordinator
