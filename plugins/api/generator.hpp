// The torch-free C++ interface of trained generators and editors (factories of kind "generator"),
// so that the CLI (`motionpipe generate`, `motionpipe edit`) and evaluation code run models without
// linking LibTorch. create() receives {"checkpoint": DIR, ...}: a directory written by the train
// stage (model.pt, model.json and the model's extra files).
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/motion/motion.h"

namespace motionpipe::plugin {

struct GenerateRequest {
  std::vector<std::string>
      texts;           // one text, or the actions of a composition (compositing baselines)
  double seconds = 4;  // text-to-motion duration (editors keep the source's length)
  int64_t frames = 0;  // > 0: exactly this many frames (overrides seconds and the source)
  double fps = 30;
  uint64_t seed = 1;
  const Motion* source = nullptr;  // editing models: the motion to edit
  int steps = 0;                   // samplers with a step count (0 = the model's default)
  std::string sampler;             // e.g. "ddpm", "ddim" ("" = default)
};

class Generator {
 public:
  virtual ~Generator() = default;
  virtual std::string Name() const = 0;
  virtual Result<Motion> Generate(const GenerateRequest& request) = 0;
  // Several requests at once (models batch them where they can; they share sampler and steps).
  virtual Result<std::vector<Motion>> GenerateBatch(const std::vector<GenerateRequest>& requests) {
    std::vector<Motion> out;
    for (const auto& r : requests) {
      auto m = Generate(r);
      if (!m.ok()) return m.status();
      out.push_back(std::move(*m));
    }
    return out;
  }
  // Totals the model counted over everything it generated so far (an editor that plants its own
  // edits' feet: the foot frames it held), by name; sums, so that a stage's tasks add up. The
  // edit stage writes them into its summary and metrics.
  virtual std::vector<std::pair<std::string, double>> Counts() const { return {}; }
  // Embeddings in the model's latent space (evaluators): of motions and of texts.
  virtual Result<std::vector<std::vector<float>>> EncodeMotions(
      const std::vector<Motion>& motions) {
    (void)motions;
    return Unimplemented(Name() + " does not encode motions");
  }
  virtual Result<std::vector<std::vector<float>>> EncodeTexts(
      const std::vector<std::string>& texts) {
    (void)texts;
    return Unimplemented(Name() + " does not encode texts");
  }
};

}  // namespace motionpipe::plugin
