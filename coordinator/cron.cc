#include "cron.h"

#include <ctime>
#include <sstream>
#include <vector>

namespace motionpipe::coordinator {

namespace {

template <size_t N>
Status ParseField(const std::string& field, int lo, int hi, const char* name, std::bitset<N>* out,
                  bool* restricted) {
  *restricted = field != "*";
  std::stringstream items(field);
  std::string item;
  while (std::getline(items, item, ',')) {
    if (item.empty()) return InvalidArgument(std::string("empty item in the ") + name + " field");
    int step = 1;
    std::string range = item;
    if (const size_t slash = item.find('/'); slash != std::string::npos) {
      range = item.substr(0, slash);
      try {
        size_t used = 0;
        step = std::stoi(item.substr(slash + 1), &used);
        if (used != item.size() - slash - 1 || step < 1) throw std::invalid_argument("step");
      } catch (...) {
        return InvalidArgument(std::string("bad step in the ") + name + " field: '" + item + "'");
      }
    }
    int a = lo, b = hi;
    if (range != "*") {
      const size_t dash = range.find('-');
      try {
        size_t used = 0;
        a = std::stoi(range.substr(0, dash), &used);
        if (used != (dash == std::string::npos ? range.size() : dash))
          throw std::invalid_argument("a");
        b = a;
        if (dash != std::string::npos) {
          b = std::stoi(range.substr(dash + 1), &used);
          if (used != range.size() - dash - 1) throw std::invalid_argument("b");
        } else if (item.find('/') != std::string::npos) {
          b = hi;  // "5/15" means from 5 every 15
        }
      } catch (...) {
        return InvalidArgument(std::string("bad value in the ") + name + " field: '" + item + "'");
      }
    }
    if (a < lo || b > hi || a > b) {
      return InvalidArgument(std::string(name) + " must be within " + std::to_string(lo) + "-" +
                             std::to_string(hi) + ": '" + item + "'");
    }
    for (int v = a; v <= b; v += step) out->set(static_cast<size_t>(v));
  }
  return Status::Ok();
}

}  // namespace

Result<CronSpec> ParseCron(const std::string& text) {
  std::string expr = text;
  if (expr == "@hourly")
    expr = "0 * * * *";
  else if (expr == "@daily" || expr == "@midnight")
    expr = "0 0 * * *";
  else if (expr == "@weekly")
    expr = "0 0 * * 0";
  else if (expr == "@monthly")
    expr = "0 0 1 * *";
  else if (expr == "@yearly" || expr == "@annually")
    expr = "0 0 1 1 *";
  std::istringstream in(expr);
  std::vector<std::string> fields;
  std::string field;
  while (in >> field) fields.push_back(field);
  if (fields.size() != 5) {
    return InvalidArgument("cron '" + text +
                           "': expected 5 fields (minute hour day month weekday), found " +
                           std::to_string(fields.size()));
  }
  CronSpec spec;
  bool restricted = false;
  std::bitset<8> weekdays;
  Status s = ParseField(fields[0], 0, 59, "minute", &spec.minutes, &restricted);
  if (s.ok()) s = ParseField(fields[1], 0, 23, "hour", &spec.hours, &restricted);
  if (s.ok()) s = ParseField(fields[2], 1, 31, "day-of-month", &spec.days, &spec.day_restricted);
  if (s.ok()) s = ParseField(fields[3], 1, 12, "month", &spec.months, &restricted);
  if (s.ok()) s = ParseField(fields[4], 0, 7, "day-of-week", &weekdays, &spec.weekday_restricted);
  if (!s.ok()) return InvalidArgument("cron '" + text + "': " + s.message());
  for (size_t d = 0; d < 7; ++d) spec.weekdays[d] = weekdays[d];
  if (weekdays[7]) spec.weekdays[0] = true;
  return spec;
}

int64_t NextFireTime(const CronSpec& spec, int64_t after_unix) {
  int64_t t = (after_unix / 60 + 1) * 60;  // next whole minute
  const int64_t limit = after_unix + 5LL * 366 * 86400;
  while (t <= limit) {
    const std::time_t tt = static_cast<std::time_t>(t);
    std::tm tm{};
    gmtime_r(&tt, &tm);
    if (!spec.months[static_cast<size_t>(tm.tm_mon + 1)]) {
      // Jump to the first minute of the next month.
      tm.tm_mon += 1;
      tm.tm_mday = 1;
      tm.tm_hour = 0;
      tm.tm_min = 0;
      tm.tm_sec = 0;
      t = static_cast<int64_t>(timegm(&tm));
      continue;
    }
    const bool dom = spec.days[static_cast<size_t>(tm.tm_mday)];
    const bool dow = spec.weekdays[static_cast<size_t>(tm.tm_wday)];
    const bool day_ok = spec.day_restricted && spec.weekday_restricted ? (dom || dow)
                        : spec.day_restricted                          ? dom
                        : spec.weekday_restricted                      ? dow
                                                                       : true;
    if (!day_ok) {
      t = (t / 86400 + 1) * 86400;
      continue;
    }
    if (!spec.hours[static_cast<size_t>(tm.tm_hour)]) {
      t = (t / 3600 + 1) * 3600;
      continue;
    }
    if (spec.minutes[static_cast<size_t>(tm.tm_min)]) return t;
    t += 60;
  }
  return -1;
}

}  // namespace motionpipe::coordinator
