#include "text_encoder.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <stdexcept>
#include <thread>

#include "motionpipe/base/file.h"
#include "motionpipe/base/job_layout.h"
#include "motionpipe/formats/npz.h"

namespace motionpipe::nn {

namespace {

std::string Lower(const std::string& s) {
  std::string out;
  for (char c : s) out.push_back(static_cast<char>(std::tolower(static_cast<unsigned char>(c))));
  return out;
}

// Words of a text: runs of letters and digits; every other visible character is a word of its own.
std::vector<std::string> Words(const std::string& text) {
  std::vector<std::string> words;
  std::string word;
  for (char c : Lower(text)) {
    const auto u = static_cast<unsigned char>(c);
    if (std::isalnum(u)) {
      word.push_back(c);
      continue;
    }
    if (!word.empty()) words.push_back(word);
    word.clear();
    if (!std::isspace(u)) words.emplace_back(1, c);
  }
  if (!word.empty()) words.push_back(word);
  return words;
}

constexpr char kEnd[] = "</w>";

// A word as its initial symbols: characters, the last one carrying the end-of-word mark.
std::vector<std::string> Symbols(const std::string& word) {
  std::vector<std::string> symbols;
  for (size_t k = 0; k < word.size(); ++k)
    symbols.push_back(std::string(1, word[k]) + (k + 1 == word.size() ? kEnd : ""));
  return symbols;
}

}  // namespace

// Byte-pair encoding (Sennrich et al.) over characters with an end-of-word mark. (Debian's
// SentencePiece bundles its own protobuf, which clashes with the protobuf LibTorch and the wire
// protocol load into the same process, so the tokenizer is our own.)
struct Tokenizer::Impl {
  std::vector<std::pair<std::string, std::string>> merges;  // in order of rank
  std::map<std::pair<std::string, std::string>, size_t> rank;
  std::map<std::string, int64_t> ids;  // symbol -> id (0 padding, 1 unknown)
};

Tokenizer::Tokenizer() : impl_(std::make_unique<Impl>()) {}
Tokenizer::~Tokenizer() = default;

void Tokenizer::Train(const std::vector<std::string>& texts, int vocab) {
  std::map<std::string, int64_t> counts;
  for (const auto& t : texts) {
    for (const auto& w : Words(t)) ++counts[w];
  }
  std::vector<std::pair<std::vector<std::string>, int64_t>> words;
  std::set<std::string> symbols;
  for (const auto& [w, c] : counts) {
    words.push_back({Symbols(w), c});
    for (const auto& s : words.back().first) symbols.insert(s);
  }
  nlohmann::json merges = nlohmann::json::array();
  while (static_cast<int>(symbols.size()) + 2 < vocab) {
    std::map<std::pair<std::string, std::string>, int64_t> pairs;
    for (const auto& [syms, c] : words) {
      for (size_t k = 0; k + 1 < syms.size(); ++k) pairs[{syms[k], syms[k + 1]}] += c;
    }
    // The most frequent pair; ties go to the first in lexicographic order (deterministic).
    std::pair<std::string, std::string> best;
    int64_t best_count = 1;
    for (const auto& [pair, c] : pairs) {
      if (c > best_count) best = pair, best_count = c;
    }
    if (best_count < 2) break;
    const std::string merged = best.first + best.second;
    for (auto& [syms, c] : words) {
      std::vector<std::string> out;
      for (size_t k = 0; k < syms.size(); ++k) {
        if (k + 1 < syms.size() && syms[k] == best.first && syms[k + 1] == best.second) {
          out.push_back(merged);
          ++k;
        } else {
          out.push_back(syms[k]);
        }
      }
      syms = std::move(out);
    }
    symbols.insert(merged);
    merges.push_back({best.first, best.second});
  }
  const nlohmann::json model = {
      {"format", "motionpipe.bpe/1"}, {"merges", merges}, {"symbols", symbols}};
  Load(model.dump());
}

void Tokenizer::Load(const std::string& serialized) {
  const nlohmann::json model = nlohmann::json::parse(serialized, nullptr, false);
  if (!model.is_object() || model.value("format", std::string()) != "motionpipe.bpe/1") {
    throw std::runtime_error("not a motionpipe BPE tokenizer");
  }
  auto impl = std::make_unique<Impl>();
  for (const auto& m : model["merges"]) {
    impl->rank[{m[0].get<std::string>(), m[1].get<std::string>()}] = impl->merges.size();
    impl->merges.emplace_back(m[0].get<std::string>(), m[1].get<std::string>());
  }
  int64_t next = 2;
  for (const auto& s : model["symbols"]) impl->ids[s.get<std::string>()] = next++;
  impl_ = std::move(impl);
  serialized_ = serialized;
}

int Tokenizer::vocab_size() const {
  return impl_->ids.empty() ? 0 : static_cast<int>(impl_->ids.size()) + 2;
}

std::vector<int64_t> Tokenizer::Encode(const std::string& text, int max_tokens) const {
  if (impl_->ids.empty()) throw std::runtime_error("the tokenizer has not been trained or loaded");
  std::vector<int64_t> ids;
  for (const auto& w : Words(text)) {
    std::vector<std::string> syms = Symbols(w);
    // Apply the lowest-ranked merge present until none applies.
    while (syms.size() > 1) {
      size_t best = impl_->merges.size(), at = 0;
      for (size_t k = 0; k + 1 < syms.size(); ++k) {
        const auto it = impl_->rank.find({syms[k], syms[k + 1]});
        if (it != impl_->rank.end() && it->second < best) best = it->second, at = k;
      }
      if (best == impl_->merges.size()) break;
      syms[at] += syms[at + 1];
      syms.erase(syms.begin() + static_cast<std::ptrdiff_t>(at) + 1);
    }
    for (const auto& s : syms) {
      if (static_cast<int>(ids.size()) >= max_tokens) return ids;
      const auto it = impl_->ids.find(s);
      ids.push_back(it == impl_->ids.end() ? 1 : it->second);
    }
  }
  if (ids.empty()) ids.push_back(1);
  return ids;
}

TextEncoderOptions TextEncoderOptions::FromJson(const nlohmann::json& j) {
  TextEncoderOptions o;
  o.kind = j.value("kind", o.kind);
  o.dim = j.value("dim", o.dim);
  o.layers = j.value("layers", o.layers);
  o.heads = j.value("heads", o.heads);
  o.ff = j.value("ff", o.ff);
  o.dropout = j.value("dropout", o.dropout);
  o.vocab = j.value("vocab", o.vocab);
  o.max_tokens = j.value("max_tokens", o.max_tokens);
  o.table = j.value("table", o.table);
  if (o.kind != "learned" && o.kind != "precomputed")
    throw std::invalid_argument("text_encoder.kind must be learned or precomputed");
  if (o.dim % o.heads != 0)
    throw std::invalid_argument("text_encoder.dim must be divisible by text_encoder.heads");
  return o;
}

nlohmann::json TextEncoderOptions::ToJson() const {
  return {{"kind", kind},  {"dim", dim},         {"layers", layers}, {"heads", heads},
          {"ff", ff},      {"dropout", dropout}, {"vocab", vocab},   {"max_tokens", max_tokens},
          {"table", table}};
}

torch::Tensor PositionalEncoding(int64_t length, int64_t dim) {
  auto position = torch::arange(length, torch::kFloat32).unsqueeze(1);
  auto div = torch::exp(torch::arange(0, dim, 2, torch::kFloat32) *
                        (-std::log(10000.0) / static_cast<double>(dim)));
  auto pe = torch::zeros({length, dim});
  pe.index_put_({torch::indexing::Slice(), torch::indexing::Slice(0, torch::indexing::None, 2)},
                torch::sin(position * div));
  pe.index_put_({torch::indexing::Slice(), torch::indexing::Slice(1, torch::indexing::None, 2)},
                torch::cos(position * div));
  return pe.unsqueeze(1);
}

TextEncoderImpl::TextEncoderImpl(const TextEncoderOptions& options) : options_(options) {
  if (options_.kind == "learned") {
    embed_ = register_module(
        "embed", torch::nn::Embedding(
                     torch::nn::EmbeddingOptions(options_.vocab + 2, options_.dim).padding_idx(0)));
    // Vaswani et al.'s scale: entries N(0, 1/dim), multiplied by sqrt(dim) in forward(), give token
    // features of unit spread like the positional encodings. torch's default N(0, 1) would reach a
    // spread of sqrt(dim) (11 at 128) and saturate the first layer's softmax, so that its query and
    // key projections get no gradient.
    torch::NoGradGuard no_grad;
    embed_->weight.normal_(0.0, 1.0 / std::sqrt(static_cast<double>(options_.dim)));
    embed_->weight[0].zero_();
  }
  encoder_ = register_module("encoder",
                             Encoder(TransformerOptions{options_.dim, options_.heads, options_.ff,
                                                        options_.layers, options_.dropout}));
  separator_ = register_parameter("separator", torch::randn({options_.dim}) * 0.02);
}

void TextEncoderImpl::Fit(const std::vector<std::string>& texts) {
  if (options_.kind == "learned") {
    if (tokenizer_.vocab_size() == 0) tokenizer_.Train(texts, options_.vocab);
    return;
  }
  if (!table_.empty()) return;
  if (options_.table.empty())
    throw std::invalid_argument(
        "text_encoder.table: the npz of precomputed embeddings is required");
  auto npz = ReadNpz(options_.table);
  if (!npz.ok()) throw std::invalid_argument(npz.status().message());
  auto texts_a = GetShaped(*npz, "texts", {-1}, options_.table);
  if (!texts_a.ok()) throw std::invalid_argument(texts_a.status().message());
  const int64_t n = (*texts_a)->shape[0];
  auto emb = GetShaped(*npz, "embeddings", {n, -1}, options_.table);
  if (!emb.ok()) throw std::invalid_argument(emb.status().message());
  auto names = (*texts_a)->ToStrings(options_.table);
  auto values = (*emb)->ToFloat32(options_.table);
  if (!names.ok() || !values.ok())
    throw std::invalid_argument(options_.table + ": texts must be strings and embeddings numbers");
  table_dim_ = (*emb)->shape[1];
  for (int64_t k = 0; k < n; ++k) {
    table_[(*names)[static_cast<size_t>(k)]] = std::vector<float>(
        values->begin() + k * table_dim_, values->begin() + (k + 1) * table_dim_);
  }
  project_ = register_module("project", torch::nn::Linear(table_dim_, options_.dim));
}

bool TextEncoderImpl::fitted() const {
  return options_.kind == "learned" ? tokenizer_.vocab_size() > 0 : !table_.empty();
}

torch::Tensor TextEncoderImpl::TokenIds(const std::vector<std::string>& texts) const {
  const auto n = static_cast<int64_t>(texts.size());
  std::vector<std::vector<int64_t>> ids;
  int64_t longest = 1;
  for (const auto& t : texts) {
    ids.push_back(tokenizer_.Encode(t, options_.max_tokens));
    longest = std::max<int64_t>(longest, static_cast<int64_t>(ids.back().size()));
  }
  auto tokens = torch::zeros({n, longest}, torch::kInt64);
  auto acc = tokens.accessor<int64_t, 2>();
  for (int64_t i = 0; i < n; ++i) {
    for (size_t k = 0; k < ids[static_cast<size_t>(i)].size(); ++k)
      acc[i][static_cast<int64_t>(k)] = ids[static_cast<size_t>(i)][k];
  }
  return tokens;
}

TextFeatures TextEncoderImpl::forward(const std::vector<std::string>& texts) {
  const auto n = static_cast<int64_t>(texts.size());
  if (options_.kind == "precomputed") {
    std::vector<float> flat;
    for (const auto& t : texts) {
      const auto it = table_.find(t);
      if (it == table_.end())
        throw std::invalid_argument("precomputed text encoder: no embedding for '" + t + "' in " +
                                    options_.table);
      flat.insert(flat.end(), it->second.begin(), it->second.end());
    }
    auto x = ApplyLinear(project_, torch::tensor(flat).view({n, table_dim_}))
                 .unsqueeze(0);  // [1, N, dim]
    return {encoder_->forward(x, {}), torch::zeros({n, 1}, torch::kBool)};
  }
  const auto tokens = TokenIds(texts);
  const int64_t longest = tokens.size(1);
  const auto padding = tokens.eq(0);
  auto x = embed_->forward(tokens).transpose(0, 1) *
           std::sqrt(static_cast<double>(options_.dim));  // [L, N, dim]
  x = x + PositionalEncoding(longest, options_.dim);
  return {encoder_->forward(x, padding), padding};
}

TextFeatures TextEncoderImpl::ForwardJoined(const std::vector<std::vector<std::string>>& texts) {
  // Each action on its own, then [a; SEP; b; ...] per example.
  std::vector<std::string> flat;
  std::vector<size_t> counts;
  for (const auto& group : texts) {
    counts.push_back(group.size());
    flat.insert(flat.end(), group.begin(), group.end());
  }
  const TextFeatures all = forward(flat);
  std::vector<torch::Tensor> sequences, masks;
  size_t at = 0;
  int64_t longest = 0;
  for (const size_t count : counts) {
    std::vector<torch::Tensor> parts, part_masks;
    for (size_t k = 0; k < count; ++k, ++at) {
      const auto keep = all.padding[static_cast<int64_t>(at)].logical_not();
      const auto idx = keep.nonzero().squeeze(1);
      parts.push_back(all.tokens.index_select(0, idx).select(1, static_cast<int64_t>(at)));
      part_masks.push_back(torch::zeros({idx.size(0)}, torch::kBool));
      if (k + 1 < count) {
        parts.push_back(separator_.unsqueeze(0));
        part_masks.push_back(torch::zeros({1}, torch::kBool));
      }
    }
    sequences.push_back(torch::cat(parts, 0));
    masks.push_back(torch::cat(part_masks, 0));
    longest = std::max(longest, sequences.back().size(0));
  }
  const auto n = static_cast<int64_t>(sequences.size());
  auto tokens = torch::zeros({longest, n, options_.dim});
  auto padding = torch::ones({n, longest}, torch::kBool);
  for (int64_t i = 0; i < n; ++i) {
    const int64_t len = sequences[static_cast<size_t>(i)].size(0);
    tokens.index_put_({torch::indexing::Slice(0, len), i}, sequences[static_cast<size_t>(i)]);
    padding.index_put_({i, torch::indexing::Slice(0, len)}, masks[static_cast<size_t>(i)]);
  }
  return {tokens, padding};
}

void TextEncoderImpl::SaveExtras(const std::string& dir) const {
  if (options_.kind == "learned" && tokenizer_.vocab_size() > 0) {
    const Status s = WriteFileAtomic(dir + "/tokenizer.model", tokenizer_.serialized());
    if (!s.ok()) throw std::runtime_error(s.message());
  }
}

void TextEncoderImpl::LoadExtras(const std::string& dir) {
  if (options_.kind == "learned") {
    auto bytes = ReadFile(dir + "/tokenizer.model");
    if (!bytes.ok())
      throw std::invalid_argument(dir + ": no tokenizer.model (" + bytes.status().message() + ")");
    tokenizer_.Load(*bytes);
  } else {
    Fit({});
  }
}

void FitShared(TextEncoder& encoder, const std::vector<std::string>& texts,
               const std::string& state_dir, int rank) {
  if (encoder->options().kind != "learned") {
    encoder->Fit({});
    return;
  }
  const std::string path = state_dir.empty() ? "" : state_dir + "/tokenizer.model";
  if (!path.empty() && std::filesystem::exists(path)) {
    encoder->LoadExtras(state_dir);
    return;
  }
  if (rank == 0 || path.empty()) {
    encoder->Fit(texts);
    if (!path.empty()) {
      std::filesystem::create_directories(state_dir);
      encoder->SaveExtras(state_dir);
    }
    return;
  }
  for (int waited = 0; !std::filesystem::exists(path); ++waited) {
    if (waited > 6000)
      throw std::runtime_error("rank " + std::to_string(rank) + ": rank 0 never wrote " + path);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  encoder->LoadExtras(state_dir);
}

std::string LoadPretrainedTextEncoder(TextEncoder& encoder, const std::string& from,
                                      const std::vector<std::string>& input_dirs, bool freeze) {
  namespace fs = std::filesystem;
  std::string dir;
  if (from == "input") {
    for (const std::string& input : input_dirs) {
      for (const std::string& candidate : {input, layout::CheckpointDir(input)}) {
        if (dir.empty() && fs::exists(layout::ModelConfigFile(candidate))) dir = candidate;
      }
    }
    if (dir.empty())
      throw std::invalid_argument(
          "text_encoder_from: input, but no stage input holds a checkpoint (model/model.json)");
  } else {
    dir = fs::exists(layout::ModelConfigFile(layout::CheckpointDir(from)))
              ? layout::CheckpointDir(from)
              : from;
  }
  auto text = ReadFile(layout::ModelConfigFile(dir));
  if (!text.ok()) throw std::invalid_argument("text_encoder_from: " + text.status().message());
  nlohmann::json theirs;
  try {
    theirs = nlohmann::json::parse(*text).at("config").at("model").at("text_encoder");
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument("text_encoder_from " + dir +
                                "/model.json: no config.model.text_encoder (" + e.what() + ")");
  }
  TextEncoder pretrained(TextEncoderOptions::FromJson(theirs));
  const nlohmann::json ours = encoder->options().ToJson();
  if (pretrained->options().ToJson() != ours) {
    throw std::invalid_argument("text_encoder_from " + dir + ": its text encoder is " +
                                pretrained->options().ToJson().dump() + ", this model's is " +
                                ours.dump() + " (use the same text_encoder settings)");
  }
  try {
    torch::serialize::InputArchive archive, sub;
    archive.load_from(layout::ModelWeightsFile(dir));
    archive.read("text_encoder", sub);
    pretrained->load(sub);
  } catch (const c10::Error& e) {
    throw std::invalid_argument("text_encoder_from " + dir +
                                "/model.pt: no text encoder weights of these settings (" +
                                e.what_without_backtrace() + ")");
  }
  torch::NoGradGuard no_grad;
  auto source = pretrained->named_parameters();
  for (auto& item : encoder->named_parameters()) item.value().copy_(source[item.key()]);
  auto source_buffers = pretrained->named_buffers();
  for (auto& item : encoder->named_buffers()) item.value().copy_(source_buffers[item.key()]);
  encoder->LoadExtras(dir);
  for (auto& item : encoder->named_parameters())
    item.value().set_requires_grad(!freeze || item.key() == "separator");
  return dir;
}

}  // namespace motionpipe::nn
