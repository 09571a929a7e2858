// ParseNpy must return an error, never crash, on any bytes; valid arrays must convert safely.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "motionpipe/formats/npy.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto array =
      motionpipe::ParseNpy(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.npy");
  if (array.ok()) {
    (void)array->ToFloat64("fuzz");
    (void)array->ToStrings("fuzz");
    (void)motionpipe::SerializeNpy(*array);
  }
  return 0;
}
