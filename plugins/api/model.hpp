// The C++ interface of trainable models (factories of kind "model"), on LibTorch. The `train` stage
// (plugins/train) drives any model through it: data, losses, checkpoints, ranks. Host code that
// only runs trained models uses the torch-free generator.hpp instead.
#pragma once

#include <torch/torch.h>

#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace motionpipe::plugin {

// Named tensors of one batch (the model chooses the names), with the texts when there are any.
struct Batch {
  std::map<std::string, torch::Tensor> tensors;
  std::vector<std::string> texts;                // one per example
  std::vector<std::vector<std::string>> groups;  // per example: its action texts (compositions)
  int64_t size = 0;
};

struct DataContext {
  nlohmann::json config;  // the stage's params.data
  std::vector<std::string>
      input_dirs;               // committed directories of the stage's inputs, results first
  std::string split = "train";  // "train" or "val"
  std::string state_dir;        // survives attempts: a place for derived files (a tokenizer)
  int rank = 0, world_size = 1;
  uint64_t seed = 1;
};

// Training examples. Get() must give the same batch for the same indices and seed (on-the-fly
// augmentation draws from `seed`), so that ranks and resumed runs see the same data.
class Dataset {
 public:
  virtual ~Dataset() = default;
  virtual int64_t size() const = 0;
  virtual Batch Get(const std::vector<int64_t>& indices, uint64_t seed) = 0;
};

class Model {
 public:
  virtual ~Model() = default;
  virtual std::string Name() const = 0;
  virtual torch::nn::Module& Module() = 0;
  // Everything needed to build the same model again (saved with every checkpoint).
  virtual nlohmann::json Config() const = 0;
  // Examples from the stage's inputs; std::invalid_argument for data the model cannot use.
  virtual std::unique_ptr<Dataset> MakeDataset(const DataContext& context) = 0;
  // Training-mode forward pass of one batch: "loss" is minimised, the other entries are logged.
  virtual std::map<std::string, torch::Tensor> Losses(const Batch& batch, int64_t step) = 0;
  // Files a checkpoint needs besides the weights (a tokenizer, normalisation statistics).
  virtual void SaveExtras(const std::string& dir) const { (void)dir; }
  virtual void LoadExtras(const std::string& dir) { (void)dir; }
};

}  // namespace motionpipe::plugin
