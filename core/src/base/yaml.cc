#include "motionpipe/base/yaml.h"

#include <yaml-cpp/yaml.h>

#include <regex>
#include <stdexcept>

namespace motionpipe {

namespace {

using Json = nlohmann::ordered_json;

struct ExpansionLimit : std::length_error {
  ExpansionLimit()
      : std::length_error("the document expands to more than " + std::to_string(kMaxYamlValues) +
                          " values (nested aliases, e.g. a \"billion laughs\" file?)") {}
};

// Counts the values made in *budget and throws ExpansionLimit past kMaxYamlValues.
Json ToJson(const YAML::Node& node, int64_t* budget) {
  if (++*budget > kMaxYamlValues) throw ExpansionLimit();
  switch (node.Type()) {
    case YAML::NodeType::Null:
    case YAML::NodeType::Undefined:
      return nullptr;
    case YAML::NodeType::Sequence: {
      Json out = Json::array();
      for (const auto& item : node) out.push_back(ToJson(item, budget));
      return out;
    }
    case YAML::NodeType::Map: {
      Json out = Json::object();
      for (const auto& item : node) out[item.first.as<std::string>()] = ToJson(item.second, budget);
      return out;
    }
    case YAML::NodeType::Scalar: {
      const std::string text = node.Scalar();
      if (node.Tag() == "!") return text;  // quoted
      if (text == "null" || text == "~" || text.empty()) return nullptr;
      if (text == "true" || text == "True") return true;
      if (text == "false" || text == "False") return false;
      static const std::regex kInt("[-+]?[0-9]+");
      static const std::regex kFloat("[-+]?([0-9]*\\.[0-9]+|[0-9]+\\.?[0-9]*)([eE][-+]?[0-9]+)?");
      if (std::regex_match(text, kInt)) {
        try {
          return std::stoll(text);
        } catch (...) {
          return text;
        }
      }
      if (std::regex_match(text, kFloat)) return std::stod(text);
      return text;
    }
  }
  return nullptr;
}

}  // namespace

Result<nlohmann::ordered_json> ParseYaml(const std::string& text, const std::string& origin) {
  try {
    int64_t budget = 0;
    return ToJson(YAML::Load(text), &budget);
  } catch (const YAML::Exception& error) {
    return InvalidArgument(origin + ":" + std::to_string(error.mark.line + 1) + ":" +
                           std::to_string(error.mark.column + 1) +
                           ": malformed YAML: " + error.msg);
  } catch (const ExpansionLimit& error) {
    return InvalidArgument(origin + ": " + error.what());
  }
}

}  // namespace motionpipe
