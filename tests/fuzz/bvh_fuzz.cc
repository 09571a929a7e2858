// ParseBvh on any text; small parsed files also go through the SMPL-22 import (retargeting).
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "motionpipe/formats/bvh.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto bvh =
      motionpipe::ParseBvh(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.bvh");
  if (bvh.ok() && bvh->frames * static_cast<int64_t>(bvh->joints.size()) < 20000) {
    motionpipe::BvhImportOptions options;
    options.fps = 0;
    (void)motionpipe::ImportBvh(*bvh, "fuzz.bvh", options);
  }
  return 0;
}
