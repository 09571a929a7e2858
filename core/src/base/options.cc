#include "motionpipe/base/options.h"

#include <algorithm>

namespace motionpipe {

Status CheckOptionKeys(const nlohmann::json& params, const nlohmann::json& defaults,
                       const std::string& origin, const std::string& what,
                       const std::vector<std::string>& other_keys) {
  if (!params.is_object()) return InvalidArgument(origin + ": a map of " + what);
  for (const auto& item : params.items()) {
    if (defaults.contains(item.key()) ||
        std::find(other_keys.begin(), other_keys.end(), item.key()) != other_keys.end())
      continue;
    std::string known;
    for (const auto& key : defaults.items()) known += (known.empty() ? "" : ", ") + key.key();
    return InvalidArgument(origin + "." + item.key() + ": unknown (known: " + known + ")");
  }
  return Status::Ok();
}

}  // namespace motionpipe
