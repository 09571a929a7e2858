// ParseBabel on any text, and the simultaneous-action sweep on what it accepts.
#include <cstddef>
#include <cstdint>
#include <string>

#include "motionpipe/formats/babel.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto sequences =
      motionpipe::ParseBabel(std::string(reinterpret_cast<const char*>(data), size), "fuzz.json");
  if (sequences.ok()) {
    for (const auto& sequence : *sequences) (void)motionpipe::SweepActionSpans(sequence, {});
  }
  return 0;
}
