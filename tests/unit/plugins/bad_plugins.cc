// Deliberately broken plugins for the plugin host's tests; one library per -D variant.
#include <stdexcept>

#include "motionpipe_plugin.h"

#if defined(BAD_ABI)
static const mp_plugin kPlugin = {
    MOTIONPIPE_PLUGIN_ABI_VERSION + 41, sizeof(mp_plugin), "bad_abi", "0", 0, nullptr, 0, nullptr};
extern "C" __attribute__((visibility("default"))) const mp_plugin* motionpipe_plugin_v1(void) {
  return &kPlugin;
}
#elif defined(THROWS)
extern "C" __attribute__((visibility("default"))) const mp_plugin* motionpipe_plugin_v1(void) {
  throw std::runtime_error("cannot find my model weights");
}
#elif defined(NO_ENTRY)
extern "C" __attribute__((visibility("default"))) int some_other_symbol(void) { return 1; }
#endif
