// The `learned` body-part labeler (plugin, LibTorch): a small fastText-style classifier trained on
// GPT-labelled action texts, predicting the six SINC parts for texts GPT never saw.
//
//   features  hashed word unigrams and bigrams and character trigrams of "<word>", 2^16 buckets
//   model     EmbeddingBag(mean) -> 128 -> ReLU -> Linear(6), sigmoid per part
//   training  binary cross-entropy, Adam, mini-batches, fixed seed (stage kind `labeler.train`)
//
// The stage writes learned_labeler.pt (the weights) and learned_labeler.json (hyper-parameters and
// the training summary). The factory ("labeler", "learned") loads them from config.model (a file or
// the directory holding them).
#include <torch/torch.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <random>

#include "../api/plugin.hpp"
#include "motionpipe/base/file.h"
#include "motionpipe/labels/labeler.h"

namespace {

using motionpipe::PartSet;
using motionpipe::Result;
using motionpipe::Status;
namespace labels = motionpipe::labels;

constexpr int64_t kBuckets = 1 << 16;
constexpr char kWeightsName[] = "learned_labeler.pt";
constexpr char kMetaName[] = "learned_labeler.json";

uint64_t Fnv1a(const std::string& s) {
  uint64_t h = 0xcbf29ce484222325ull;
  for (const unsigned char c : s) {
    h ^= c;
    h *= 0x100000001b3ull;
  }
  return h;
}

// Feature bucket ids of a text.
std::vector<int64_t> Features(const std::string& text) {
  std::vector<std::string> words;
  std::string word;
  for (char c : text + " ") {
    const auto u = static_cast<unsigned char>(c);
    if (std::isalnum(u)) {
      word.push_back(static_cast<char>(std::tolower(u)));
    } else if (!word.empty()) {
      words.push_back(word);
      word.clear();
    }
  }
  std::vector<int64_t> ids;
  for (size_t k = 0; k < words.size(); ++k) {
    ids.push_back(static_cast<int64_t>(Fnv1a("w:" + words[k]) % kBuckets));
    if (k + 1 < words.size())
      ids.push_back(static_cast<int64_t>(Fnv1a("b:" + words[k] + " " + words[k + 1]) % kBuckets));
    const std::string padded = "<" + words[k] + ">";
    for (size_t c = 0; c + 3 <= padded.size(); ++c)
      ids.push_back(static_cast<int64_t>(Fnv1a("c:" + padded.substr(c, 3)) % kBuckets));
  }
  if (ids.empty()) ids.push_back(0);
  return ids;
}

struct ClassifierImpl : torch::nn::Module {
  ClassifierImpl(int64_t dim, int64_t hidden)
      : embed(register_module(
            "embed", torch::nn::EmbeddingBag(
                         torch::nn::EmbeddingBagOptions(kBuckets, dim).mode(torch::kMean)))),
        fc1(register_module("fc1", torch::nn::Linear(dim, hidden))),
        fc2(register_module("fc2", torch::nn::Linear(hidden, motionpipe::kNumBodyParts))) {}
  torch::Tensor forward(const torch::Tensor& ids, const torch::Tensor& offsets) {
    return fc2(torch::relu(fc1(embed(ids, offsets))));
  }
  torch::nn::EmbeddingBag embed;
  torch::nn::Linear fc1, fc2;
};
TORCH_MODULE(Classifier);

// Packs texts for EmbeddingBag: concatenated ids + start offsets.
std::pair<torch::Tensor, torch::Tensor> Pack(const std::vector<std::vector<int64_t>>& features,
                                             const std::vector<size_t>& rows) {
  std::vector<int64_t> ids, offsets;
  for (const size_t r : rows) {
    offsets.push_back(static_cast<int64_t>(ids.size()));
    ids.insert(ids.end(), features[r].begin(), features[r].end());
  }
  return {torch::tensor(ids, torch::kInt64), torch::tensor(offsets, torch::kInt64)};
}

class LearnedLabeler : public labels::Labeler {
 public:
  LearnedLabeler(Classifier model, double threshold)
      : model_(std::move(model)), threshold_(threshold) {
    model_->eval();
  }
  std::string Name() const override { return "learned"; }
  Result<std::vector<PartSet>> Label(const std::vector<labels::LabelInput>& inputs) override {
    torch::NoGradGuard no_grad;
    std::vector<std::vector<int64_t>> features;
    for (const auto& input : inputs) features.push_back(Features(input.text));
    std::vector<PartSet> out;
    const size_t batch = 1024;
    for (size_t start = 0; start < inputs.size(); start += batch) {
      std::vector<size_t> rows(std::min(batch, inputs.size() - start));
      std::iota(rows.begin(), rows.end(), start);
      auto [ids, offsets] = Pack(features, rows);
      const torch::Tensor prob = torch::sigmoid(model_->forward(ids, offsets));
      const auto acc = prob.accessor<float, 2>();
      for (int64_t r = 0; r < prob.size(0); ++r) {
        PartSet parts = 0;
        for (int p = 0; p < motionpipe::kNumBodyParts; ++p) {
          if (acc[r][p] > threshold_) parts |= static_cast<PartSet>(1u << p);
        }
        out.push_back(parts);
      }
    }
    return out;
  }

 private:
  Classifier model_;
  double threshold_;
};

std::string ModelPath(const std::string& model) {
  return std::filesystem::is_directory(model) ? model + "/" + kWeightsName : model;
}

Result<Classifier> LoadClassifier(const std::string& model) {
  const std::string weights = ModelPath(model);
  const std::string meta_path =
      std::filesystem::path(weights).parent_path().string() + "/" + kMetaName;
  MP_ASSIGN_OR_RETURN(const std::string meta_text, motionpipe::ReadFile(meta_path));
  const nlohmann::json meta = nlohmann::json::parse(meta_text, nullptr, false);
  if (!meta.is_object()) return motionpipe::DataLoss(meta_path + ": not JSON");
  Classifier net(meta.value("dim", 64), meta.value("hidden", 128));
  try {
    torch::load(net, weights);
  } catch (const c10::Error& e) {
    return motionpipe::DataLoss(weights +
                                ": cannot load the classifier: " + e.what_without_backtrace());
  }
  return net;
}

void* Create(const char* config_json, char* error, size_t error_size) {
  try {
    const nlohmann::json config = nlohmann::json::parse(config_json ? config_json : "{}");
    const std::string model = config.value("model", std::string());
    if (model.empty()) {
      std::snprintf(error, error_size,
                    "learned labeler: config.model must name the trained model (learned_labeler.pt "
                    "or its directory)");
      return nullptr;
    }
    auto net = LoadClassifier(model);
    if (!net.ok()) {
      std::snprintf(error, error_size, "%s", net.status().message().c_str());
      return nullptr;
    }
    torch::set_num_threads(std::max(1, config.value("threads", 1)));
    return static_cast<labels::Labeler*>(
        new LearnedLabeler(std::move(*net), config.value("threshold", 0.5)));
  } catch (const std::exception& e) {
    std::snprintf(error, error_size, "learned labeler: %s", e.what());
    return nullptr;
  }
}

void Destroy(void* object) { delete static_cast<labels::Labeler*>(object); }

// Stage `labeler.train`: trains on the training split of GPT-labelled texts (the held-out split is
// kept for evaluation), optionally plus a corpus's labelled texts.
void Train(const motionpipe::plugin::Task& task) {
  const auto& p = task.params();
  const std::string gpt = p.value("gpt", std::string("data/text/babel_action_labels_gpt3.json"));
  const int epochs = p.value("epochs", 12);
  const int64_t dim = p.value("dim", 64), hidden = p.value("hidden", 128);
  const double lr = p.value("lr", 0.01);
  const int batch = p.value("batch", 64);
  const uint64_t seed = p.value("seed", task.spec.value("seed", uint64_t{1}));
  torch::manual_seed(seed);
  torch::set_num_threads(std::max(1, task.spec.value("threads", 1)));

  auto answers = labels::LoadGptAnswers(gpt, p.value("answer", 2));
  if (!answers.ok()) throw motionpipe::plugin::BadInput(answers.status().message());
  std::vector<std::string> texts;
  std::vector<PartSet> targets;
  for (size_t k = 0; k < answers->texts.size(); ++k) {
    if (labels::IsHeldOut(answers->texts[k])) continue;  // the evaluation split stays unseen
    texts.push_back(answers->texts[k]);
    targets.push_back(answers->parts[k]);
  }
  if (texts.empty()) throw motionpipe::plugin::BadInput(gpt + ": no training texts");
  std::vector<std::vector<int64_t>> features;
  for (const auto& t : texts) features.push_back(Features(t));
  std::vector<float> y(texts.size() * motionpipe::kNumBodyParts);
  for (size_t k = 0; k < texts.size(); ++k) {
    for (int p2 = 0; p2 < motionpipe::kNumBodyParts; ++p2)
      y[k * motionpipe::kNumBodyParts + static_cast<size_t>(p2)] =
          ((targets[k] >> p2) & 1u) ? 1.f : 0.f;
  }
  const torch::Tensor target_all =
      torch::tensor(y).view({static_cast<int64_t>(texts.size()), motionpipe::kNumBodyParts});

  Classifier net(dim, hidden);
  torch::optim::Adam optimizer(net->parameters(), torch::optim::AdamOptions(lr));
  std::mt19937_64 rng(seed);
  std::vector<size_t> order(texts.size());
  std::iota(order.begin(), order.end(), 0);
  double loss_sum = 0;
  for (int epoch = 0; epoch < epochs; ++epoch) {
    if (task.cancelled()) throw std::runtime_error("cancelled");
    std::shuffle(order.begin(), order.end(), rng);
    loss_sum = 0;
    int steps = 0;
    for (size_t start = 0; start < order.size(); start += static_cast<size_t>(batch)) {
      std::vector<size_t> rows(
          order.begin() + static_cast<std::ptrdiff_t>(start),
          order.begin() + static_cast<std::ptrdiff_t>(
                              std::min(order.size(), start + static_cast<size_t>(batch))));
      auto [ids, offsets] = Pack(features, rows);
      std::vector<int64_t> index(rows.begin(), rows.end());
      const torch::Tensor target = target_all.index_select(0, torch::tensor(index, torch::kInt64));
      optimizer.zero_grad();
      const torch::Tensor loss =
          torch::binary_cross_entropy_with_logits(net->forward(ids, offsets), target);
      loss.backward();
      optimizer.step();
      loss_sum += loss.item<double>();
      ++steps;
    }
    loss_sum /= std::max(1, steps);
    task.Log(MP_LOG_INFO, "labeler.train epoch " + std::to_string(epoch + 1) + "/" +
                              std::to_string(epochs) + " loss " + std::to_string(loss_sum));
  }
  std::filesystem::create_directories(task.output_dir());
  const std::string weights = task.output_dir() + "/" + kWeightsName;
  torch::save(net, weights + ".tmp");
  std::filesystem::rename(weights + ".tmp", weights);
  const nlohmann::json meta = {{"dim", dim},
                               {"hidden", hidden},
                               {"buckets", kBuckets},
                               {"epochs", epochs},
                               {"lr", lr},
                               {"batch", batch},
                               {"seed", seed},
                               {"texts", texts.size()},
                               {"final_loss", loss_sum},
                               {"source", gpt},
                               {"split", "train (IsHeldOut == false)"}};
  const Status s =
      motionpipe::WriteFileAtomic(task.output_dir() + "/" + kMetaName, meta.dump(1) + "\n");
  if (!s.ok()) throw std::runtime_error(s.message());
  task.Metric("final_loss", loss_sum);
  task.Metric("texts", static_cast<double>(texts.size()));
}

const mp_stage_kind kKinds[] = {
    {"labeler.train", "train the learned body-part labeler on GPT-labelled texts",
     [](const mp_task_io* io, char* error, size_t size) {
       return motionpipe::plugin::RunStage(io, error, size, Train);
     }},
};

const mp_object_factory kFactories[] = {{"labeler", "learned", Create, Destroy}};

const mp_plugin kPlugin = {MOTIONPIPE_PLUGIN_ABI_VERSION,
                           sizeof(mp_plugin),
                           "labelers",
                           "1.0.0",
                           1,
                           kKinds,
                           1,
                           kFactories};

}  // namespace

extern "C" __attribute__((visibility("default"))) const mp_plugin* motionpipe_plugin_v1(void) {
  return &kPlugin;
}
