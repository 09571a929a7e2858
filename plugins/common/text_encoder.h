// Text encoders for the models (plugin kind `text_encoder`). CLIP and DistilBERT weights cannot be
// had offline, so:
//   learned      a byte-pair-encoding tokenizer trained on the training texts + token embeddings +
//   a small
//                transformer encoder; trained with the model, or pre-trained contrastively (the TMR
//                configuration of temos_sinc) and loaded frozen from that checkpoint;
//   precomputed  an npz of texts and their embeddings (CLIP, DistilBERT computed elsewhere): the
//                paper's exact setting. A text missing from the table is an error that names it.
// Both give per-text token features [L, N, dim] (sequence first) and a padding mask [N, L].
#pragma once

#include <torch/torch.h>

#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "transformer.h"

namespace motionpipe::nn {

// A byte-pair-encoding subword tokenizer, trained from texts or loaded from its JSON form.
class Tokenizer {
 public:
  Tokenizer();
  ~Tokenizer();
  // Trains on `texts` (vocabulary at most `vocab`, smaller when the texts are few); deterministic.
  void Train(const std::vector<std::string>& texts, int vocab);
  void Load(const std::string& serialized);
  const std::string& serialized() const { return serialized_; }
  int vocab_size() const;
  // Ids of the subwords, clipped to `max_tokens` (0 is padding, 1 an unknown symbol).
  std::vector<int64_t> Encode(const std::string& text, int max_tokens) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::string serialized_;
};

struct TextFeatures {
  torch::Tensor tokens;   // [L, N, dim]
  torch::Tensor padding;  // [N, L] bool, true = padding
};

struct TextEncoderOptions {
  std::string kind = "learned";  // learned | precomputed
  int64_t dim = 256;
  int64_t layers = 2;
  int64_t heads = 4;
  int64_t ff = 512;
  double dropout = 0.1;
  int vocab = 1000;
  int max_tokens = 32;
  std::string table;  // precomputed: npz with `texts` <U (N,) and `embeddings` f4 (N, D)
  static TextEncoderOptions FromJson(const nlohmann::json& j);
  nlohmann::json ToJson() const;
};

class TextEncoderImpl : public torch::nn::Module {
 public:
  explicit TextEncoderImpl(const TextEncoderOptions& options);
  // The tokenizer (learned) or table (precomputed) from the training texts, before training starts.
  void Fit(const std::vector<std::string>& texts);
  bool fitted() const;
  TextFeatures forward(const std::vector<std::string>& texts);
  // Learned: the subword ids [N, L] (0 = padding) that forward() embeds.
  torch::Tensor TokenIds(const std::vector<std::string>& texts) const;
  // Token features of several texts per example joined with a learned separator (SINC-STE).
  TextFeatures ForwardJoined(const std::vector<std::vector<std::string>>& texts);
  // Tokenizer or table files in a checkpoint directory.
  void SaveExtras(const std::string& dir) const;
  void LoadExtras(const std::string& dir);
  const TextEncoderOptions& options() const { return options_; }

 private:
  TextEncoderOptions options_;
  Tokenizer tokenizer_;
  std::map<std::string, std::vector<float>> table_;
  int64_t table_dim_ = 0;
  torch::nn::Embedding embed_{nullptr};
  torch::nn::Linear project_{nullptr};  // precomputed embeddings -> dim
  Encoder encoder_{nullptr};
  torch::Tensor separator_;
};
TORCH_MODULE(TextEncoder);

// Fits a training run's text encoder once for all its ranks: rank 0 trains the tokenizer (or loads
// the table) and writes it into state_dir, the other ranks and resumed runs load that file, so
// every rank has the same vocabulary. An empty state_dir fits locally.
void FitShared(TextEncoder& encoder, const std::vector<std::string>& texts,
               const std::string& state_dir, int rank);

// Copies the text encoder of a trained checkpoint (its tokenizer and weights) into `encoder`: the
// role DistilBERT/CLIP play in the papers, taken here by a TMR trained contrastively on motions
// (REFERENCE 5). `from` is a checkpoint directory (model.json with config.model.text_encoder,
// model.pt, tokenizer.model), a stage directory holding one in model/, or "input": the first of
// `input_dirs` that holds one. The checkpoint's text_encoder settings must equal `encoder`'s; an
// error names the directory and both. When `freeze`, every weight but SINC-STE's separator (this
// model's own) stops training. Returns the checkpoint directory used.
std::string LoadPretrainedTextEncoder(TextEncoder& encoder, const std::string& from,
                                      const std::vector<std::string>& input_dirs, bool freeze);

// Sinusoidal positional encodings [length, 1, dim].
torch::Tensor PositionalEncoding(int64_t length, int64_t dim);

}  // namespace motionpipe::nn
