// Option maps read from a config's params: what every reader of such a map checks first.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"

namespace motionpipe {

// InvalidArgument naming `origin` when `params` is not a map ("ORIGIN: a map of WHAT"), or naming
// the first key that is neither one of `defaults`' (the options' own keys, with their defaults) nor
// one of `other_keys` (the caller's own), with the known keys listed: a misspelt option must not
// pass for its default.
Status CheckOptionKeys(const nlohmann::json& params, const nlohmann::json& defaults,
                       const std::string& origin, const std::string& what,
                       const std::vector<std::string>& other_keys = {});

}  // namespace motionpipe
