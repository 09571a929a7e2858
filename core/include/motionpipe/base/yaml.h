// YAML documents as JSON: the pipeline files and the papers' tables (configs/papers/*.yaml) are
// read through one converter.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>

#include "motionpipe/base/status.h"

namespace motionpipe {

// A document expands to at most this many values: YAML aliases share nodes, and a 600-byte
// "billion laughs" file of nested aliases expands to billions of them in JSON (issue 17).
inline constexpr int64_t kMaxYamlValues = 200000;

// YAML text -> JSON with scalar types inferred as YAML 1.2's core schema does (quoted scalars stay
// strings), keys in document order. Malformed YAML is InvalidArgument naming origin:line:column;
// so is a document that expands past kMaxYamlValues values.
Result<nlohmann::ordered_json> ParseYaml(const std::string& text, const std::string& origin);

}  // namespace motionpipe
