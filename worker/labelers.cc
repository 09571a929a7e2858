#include "labelers.h"

namespace motionpipe::worker {

namespace {

// A plugin's labeler object: calls go straight to it; the plugin's factory destroys it.
class PluginLabeler : public labels::Labeler {
 public:
  PluginLabeler(labels::Labeler* object, const mp_object_factory* factory)
      : object_(object), factory_(factory) {}
  ~PluginLabeler() override { factory_->destroy(object_); }
  std::string Name() const override { return object_->Name(); }
  bool NeedsMotion() const override { return object_->NeedsMotion(); }
  Result<std::vector<PartSet>> Label(const std::vector<labels::LabelInput>& inputs) override {
    return object_->Label(inputs);
  }

 private:
  labels::Labeler* object_;
  const mp_object_factory* factory_;
};

}  // namespace

Result<std::unique_ptr<labels::Labeler>> MakeLabeler(const std::string& name,
                                                     const nlohmann::json& config,
                                                     const PluginHost* plugins) {
  auto builtin = labels::MakeBuiltinLabeler(name, config);
  if (builtin.ok() || builtin.status().code() != StatusCode::kNotFound ||
      builtin.status().message().rfind("no built-in", 0) != 0) {
    return builtin;
  }
  const mp_object_factory* factory = plugins ? plugins->FindFactory("labeler", name) : nullptr;
  if (!factory) {
    std::string known;
    for (const auto& n : labels::BuiltinLabelerNames()) known += (known.empty() ? "" : ", ") + n;
    return NotFound("no labeler '" + name + "' (built in: " + known +
                    "; plugins add more, e.g. 'learned')");
  }
  char error[1024] = {0};
  void* object = factory->create(config.dump().c_str(), error, sizeof error);
  if (!object)
    return InvalidArgument("labeler '" + name + "': " +
                           std::string(error[0] ? error : "the plugin could not create it"));
  return std::unique_ptr<labels::Labeler>(
      new PluginLabeler(static_cast<labels::Labeler*>(object), factory));
}

}  // namespace motionpipe::worker
