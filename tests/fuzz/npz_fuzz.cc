// The zip container and every reader of our npz layouts (clips, triplets, AMASS) on any bytes.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "motionpipe/formats/amass.h"
#include "motionpipe/formats/clip.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/formats/npz.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto npz =
      motionpipe::ParseNpz(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.npz");
  if (npz.ok()) {
    (void)motionpipe::ClipsFromNpz(*npz, "fuzz.npz");
    (void)motionpipe::TripletsFromNpz(*npz, "fuzz.npz");
    (void)motionpipe::AmassClipFromNpz(*npz, "fuzz.npz");
  }
  return 0;
}
