#include "temos.h"

#include <cctype>
#include <cmath>
#include <map>
#include <set>
#include <sstream>
#include <stdexcept>

#include "motionpipe/eval/metrics.h"

namespace motionpipe::temos {

namespace {

using torch::indexing::Slice;

nn::TransformerOptions Layers(const TemosOptions& o) {
  return {o.latent, o.heads, o.ff, o.layers, o.dropout};
}

// 1 on a batch's unpadded frames, 0 on its padding: [T, N, 1] from padding [N, T] (true = pad).
torch::Tensor FrameMask(const torch::Tensor& padding, torch::ScalarType dtype) {
  return padding.logical_not().transpose(0, 1).unsqueeze(2).to(dtype);
}

}  // namespace

torch::Tensor NearDuplicates(const std::vector<std::vector<std::string>>& texts, double threshold) {
  const auto n = static_cast<int64_t>(texts.size());
  std::vector<std::map<std::string, double>> bags(static_cast<size_t>(n));
  std::vector<double> norms(static_cast<size_t>(n), 0);
  for (int64_t i = 0; i < n; ++i) {
    std::string joined;
    for (const auto& t : texts[static_cast<size_t>(i)]) joined += t + " ";
    std::string word;
    for (char c : joined + " ") {
      if (std::isalnum(static_cast<unsigned char>(c))) {
        word.push_back(static_cast<char>(std::tolower(static_cast<unsigned char>(c))));
      } else if (!word.empty()) {
        bags[static_cast<size_t>(i)][word] += 1;
        word.clear();
      }
    }
    for (const auto& [w, c] : bags[static_cast<size_t>(i)]) norms[static_cast<size_t>(i)] += c * c;
    norms[static_cast<size_t>(i)] = std::sqrt(norms[static_cast<size_t>(i)]);
  }
  auto out = torch::zeros({n, n}, torch::kBool);
  auto acc = out.accessor<bool, 2>();
  for (int64_t i = 0; i < n; ++i) {
    for (int64_t j = i + 1; j < n; ++j) {
      double dot = 0;
      for (const auto& [w, c] : bags[static_cast<size_t>(i)]) {
        const auto it = bags[static_cast<size_t>(j)].find(w);
        if (it != bags[static_cast<size_t>(j)].end()) dot += c * it->second;
      }
      const double denom = norms[static_cast<size_t>(i)] * norms[static_cast<size_t>(j)];
      if (denom > 0 && dot / denom > threshold) acc[i][j] = acc[j][i] = true;
    }
  }
  return out;
}

TemosOptions TemosOptions::FromJson(const nlohmann::json& j) {
  TemosOptions o;
  o.latent = j.value("latent", o.latent);
  o.layers = j.value("layers", o.layers);
  o.heads = j.value("heads", o.heads);
  o.ff = j.value("ff", o.ff);
  o.dropout = j.value("dropout", o.dropout);
  o.kl_weight = j.value("kl_weight", o.kl_weight);
  o.latent_weight = j.value("latent_weight", o.latent_weight);
  o.text_reconstruction = j.value("text_reconstruction", o.text_reconstruction);
  if (o.text_reconstruction < 0) throw std::invalid_argument("text_reconstruction must be >= 0");
  o.latent_noise = j.value("latent_noise", o.latent_noise);
  if (o.latent_noise < 0) throw std::invalid_argument("latent_noise must be >= 0");
  o.decoder = j.value("decoder", o.decoder);
  if (o.decoder != "memory" && o.decoder != "film")
    throw std::invalid_argument("decoder must be memory or film, not '" + o.decoder + "'");
  o.velocity_weight = j.value("velocity_weight", o.velocity_weight);
  if (o.velocity_weight < 0) throw std::invalid_argument("velocity_weight must be >= 0");
  o.contrastive = j.value("contrastive", o.contrastive);
  o.temperature = j.value("temperature", o.temperature);
  o.duplicate_threshold = j.value("duplicate_threshold", o.duplicate_threshold);
  o.separate_texts = j.value("separate_texts", o.separate_texts);
  nlohmann::json text = j.value("text_encoder", nlohmann::json::object());
  if (!text.contains("dim")) text["dim"] = o.latent;
  if (!text.contains("dropout")) text["dropout"] = o.dropout;
  o.text = nn::TextEncoderOptions::FromJson(text);
  if (o.latent % o.heads != 0) {
    throw std::invalid_argument("latent (" + std::to_string(o.latent) +
                                ") must be divisible by heads (" + std::to_string(o.heads) + ")");
  }
  return o;
}

nlohmann::json TemosOptions::ToJson() const {
  return {{"latent", latent},
          {"layers", layers},
          {"heads", heads},
          {"ff", ff},
          {"dropout", dropout},
          {"kl_weight", kl_weight},
          {"latent_weight", latent_weight},
          {"text_reconstruction", text_reconstruction},
          {"latent_noise", latent_noise},
          {"decoder", decoder},
          {"velocity_weight", velocity_weight},
          {"contrastive", contrastive},
          {"temperature", temperature},
          {"duplicate_threshold", duplicate_threshold},
          {"separate_texts", separate_texts},
          {"text_encoder", text.ToJson()}};
}

VaeEncoderImpl::VaeEncoderImpl(int64_t input_dim, const TemosOptions& o) : latent_(o.latent) {
  project_ = register_module("project", torch::nn::Linear(input_dim, o.latent));
  mu_token_ = register_parameter("mu_token", torch::randn({o.latent}) * 0.02);
  logvar_token_ = register_parameter("logvar_token", torch::randn({o.latent}) * 0.02);
  encoder_ = register_module("encoder", nn::Encoder(Layers(o)));
}

std::pair<torch::Tensor, torch::Tensor> VaeEncoderImpl::forward(const torch::Tensor& x,
                                                                const torch::Tensor& padding) {
  const int64_t n = x.size(1), length = x.size(0);
  auto h = nn::ApplyLinear(project_, x);
  auto tokens = torch::stack({mu_token_, logvar_token_}).unsqueeze(1).expand({2, n, latent_});
  h = torch::cat({tokens, h}, 0) + nn::PositionalEncoding(length + 2, latent_);
  const auto mask = torch::cat({torch::zeros({n, 2}, torch::kBool), padding}, 1);
  const auto out = encoder_->forward(h, mask);
  return {out[0], out[1]};
}

DecoderImpl::DecoderImpl(const TemosOptions& o) : latent_(o.latent), layers_(o.layers) {
  decoder_ = register_module("decoder", nn::OneTokenDecoder(Layers(o)));
  out_ = register_module("out", torch::nn::Linear(o.latent, kFeatureDim));
  if (o.decoder == "film") {
    // Zero-initialised (as DiT's adaLN-Zero): the decoder starts as TEMOS's.
    film_ = register_module("film", torch::nn::Linear(o.latent, o.layers * 2 * o.latent));
    torch::NoGradGuard no_grad;
    film_->weight.zero_();
    film_->bias.zero_();
  }
}

torch::Tensor DecoderImpl::forward(const torch::Tensor& z, const torch::Tensor& padding) {
  const int64_t n = z.size(0), length = padding.size(1);
  const auto queries = nn::PositionalEncoding(length, latent_).expand({length, n, latent_});
  torch::Tensor modulation;
  if (film_) modulation = nn::ApplyLinear(film_, z).view({n, layers_, 2 * latent_}).transpose(0, 1);
  const auto h = decoder_->forward(queries, z, padding, modulation);
  auto y = nn::ApplyLinear(out_, h);
  return y.masked_fill(padding.transpose(0, 1).unsqueeze(2), 0.0);
}

TemosImpl::TemosImpl(const TemosOptions& o) : options_(o) {
  text_encoder_ = register_module("text_encoder", nn::TextEncoder(o.text));
  text_vae_ = register_module("text_vae", VaeEncoder(o.text.dim, o));
  motion_vae_ = register_module("motion_vae", VaeEncoder(kFeatureDim, o));
  decoder_ = register_module("decoder", Decoder(o));
}

Distribution TemosImpl::EncodeText(const std::vector<std::vector<std::string>>& texts,
                                   bool sample) {
  nn::TextFeatures features;
  if (options_.separate_texts) {
    features = text_encoder_->ForwardJoined(texts);
  } else {
    std::vector<std::string> flat;
    for (const auto& group : texts) {
      std::string joined;
      for (size_t k = 0; k < group.size(); ++k) joined += (k ? " while " : "") + group[k];
      flat.push_back(joined);
    }
    features = text_encoder_->forward(flat);
  }
  auto [mu, logvar] = text_vae_->forward(features.tokens, features.padding);
  return {mu, logvar, sample ? mu + torch::exp(0.5 * logvar) * torch::randn_like(mu) : mu};
}

Distribution TemosImpl::EncodeMotion(const torch::Tensor& features, const torch::Tensor& padding,
                                     bool sample) {
  auto [mu, logvar] = motion_vae_->forward(features, padding);
  return {mu, logvar, sample ? mu + torch::exp(0.5 * logvar) * torch::randn_like(mu) : mu};
}

torch::Tensor ExampleNoise(const torch::Tensor& seeds, int64_t rows, int64_t latent) {
  const auto s = seeds.to(torch::kInt64).contiguous();
  std::vector<torch::Tensor> noise;
  for (int64_t i = 0; i < s.size(0); ++i) {
    auto generator =
        at::make_generator<at::CPUGeneratorImpl>(static_cast<uint64_t>(s.data_ptr<int64_t>()[i]));
    noise.push_back(torch::randn({rows, latent}, generator));
  }
  return torch::stack(noise, 1);  // [rows, N, latent]
}

std::map<std::string, torch::Tensor> TemosImpl::Losses(
    const std::vector<std::vector<std::string>>& texts, const torch::Tensor& features,
    const torch::Tensor& padding, const torch::Tensor& example_seeds) {
  Distribution t = EncodeText(texts, false);
  Distribution m = EncodeMotion(features, padding, false);
  // Reparameterisation: z = mu + sigma * eps, eps per example from its seed when the trainer gives
  // seeds (the same eps whichever rank the example lands on), else from torch's generator.
  const auto eps = example_seeds.defined() ? ExampleNoise(example_seeds, 2, t.mu.size(1))
                                           : torch::randn({2, t.mu.size(0), t.mu.size(1)});
  t.z = t.mu + options_.latent_noise * torch::exp(0.5 * t.logvar) * eps[0];
  m.z = m.mu + options_.latent_noise * torch::exp(0.5 * m.logvar) * eps[1];
  std::map<std::string, torch::Tensor> out;
  // Both branches decode in one batch [text; motion] (the same layers; bigger matrix products).
  const int64_t n = features.size(1);
  const auto decoded = Decode(torch::cat({t.z, m.z}), padding.repeat({2, 1}));
  out["recon_text"] = MaskedSmoothL1(decoded.narrow(1, 0, n), features, padding);
  out["recon_motion"] = MaskedSmoothL1(decoded.narrow(1, n, n), features, padding);
  const auto zeros = torch::zeros_like(m.mu);
  out["kl_text_motion"] = KlDivergence(t.mu, t.logvar, m.mu, m.logvar);
  out["kl_motion_text"] = KlDivergence(m.mu, m.logvar, t.mu, t.logvar);
  out["kl_text"] = KlDivergence(t.mu, t.logvar, zeros, zeros);
  out["kl_motion"] = KlDivergence(m.mu, m.logvar, zeros, zeros);
  out["latent"] = torch::smooth_l1_loss(t.z, m.z);
  auto loss = options_.text_reconstruction * out["recon_text"] + out["recon_motion"] +
              options_.kl_weight * (out["kl_text_motion"] + out["kl_motion_text"] + out["kl_text"] +
                                    out["kl_motion"]) +
              options_.latent_weight * out["latent"];
  if (options_.velocity_weight > 0) {
    out["velocity_text"] = MaskedVelocitySmoothL1(decoded.narrow(1, 0, n), features, padding);
    out["velocity_motion"] = MaskedVelocitySmoothL1(decoded.narrow(1, n, n), features, padding);
    loss = loss + options_.velocity_weight * (options_.text_reconstruction * out["velocity_text"] +
                                              out["velocity_motion"]);
  }
  if (options_.contrastive > 0) {
    out["contrastive"] = InfoNce(t.mu, m.mu, options_.temperature,
                                 NearDuplicates(texts, options_.duplicate_threshold));
    loss = loss + options_.contrastive * out["contrastive"];
  }
  out["retrieval_r1"] = BatchRetrievalR1(t.mu, m.mu);
  out["loss"] = loss;
  return out;
}

torch::Tensor MaskedSmoothL1(const torch::Tensor& prediction, const torch::Tensor& target,
                             const torch::Tensor& padding) {
  const auto keep = FrameMask(padding, prediction.scalar_type());  // [T, N, 1]
  const auto loss = torch::smooth_l1_loss(prediction, target, torch::Reduction::None) * keep;
  // Each motion's mean over its own frames and features, then the mean over motions: a batch's loss
  // is the mean of its examples' losses, so ranks that split a batch reproduce it exactly.
  const std::vector<int64_t> frames_features = {0, 2};
  const auto per_example =
      loss.sum(frames_features) / (keep.sum(frames_features) * prediction.size(2)).clamp_min(1.0);
  return per_example.mean();
}

torch::Tensor MaskedVelocitySmoothL1(const torch::Tensor& prediction, const torch::Tensor& target,
                                     const torch::Tensor& padding) {
  const int64_t frames = target.size(0);
  if (frames < 2) return torch::zeros({}, prediction.options());
  auto delta = [frames](const torch::Tensor& x) {
    return x.narrow(0, 1, frames - 1) - x.narrow(0, 0, frames - 1);
  };
  // A pair is kept when both frames are (padding is a suffix, so when the later one is).
  const auto pair_padding = padding.narrow(1, 1, frames - 1);
  const auto keep = FrameMask(pair_padding, target.scalar_type());
  const auto target_delta = delta(target);
  // One scale for the batch (the root mean square of its target differences, detached). Each
  // example's own, tried first, magnified the motions held still (differences near 0): the
  // decoder stopped using the latent (both branches' reconstructions alike, 0.22 against 0.13
  // without the term at step 659). With ranks splitting a batch each rank uses its share's.
  const auto rms =
      ((target_delta.pow(2) * keep).sum() / (keep.sum() * target.size(2)).clamp_min(1.0))
          .sqrt()
          .clamp_min(1e-6)
          .detach();
  return MaskedSmoothL1(delta(prediction) / rms, target_delta / rms, pair_padding);
}

torch::Tensor KlDivergence(const torch::Tensor& mu_q, const torch::Tensor& logvar_q,
                           const torch::Tensor& mu_p, const torch::Tensor& logvar_p) {
  // 0.5 * sum(logvar_p - logvar_q + (exp(logvar_q) + (mu_q - mu_p)^2) / exp(logvar_p) - 1)
  const auto kl =
      0.5 * (logvar_p - logvar_q +
             (torch::exp(logvar_q) + (mu_q - mu_p).pow(2)) / torch::exp(logvar_p) - 1.0);
  // The mean over every element, as TEMOS, TMR and SINC's `kl_divergence(q, p).mean()`: their KL
  // weight 1e-5 is per latent dimension (a sum over the dimensions would weigh it `latent` times).
  return kl.mean();
}

torch::Tensor InfoNce(const torch::Tensor& a, const torch::Tensor& b, double temperature,
                      const torch::Tensor& duplicate) {
  const auto an =
      torch::nn::functional::normalize(a, torch::nn::functional::NormalizeFuncOptions().dim(1));
  const auto bn =
      torch::nn::functional::normalize(b, torch::nn::functional::NormalizeFuncOptions().dim(1));
  auto logits = torch::mm(an, bn.t()) / temperature;
  // Near-duplicates are not negatives (the diagonal is never masked).
  logits = logits.masked_fill(duplicate, -1e9);
  const auto target = torch::arange(a.size(0), torch::kInt64);
  return 0.5 * (torch::nn::functional::cross_entropy(logits, target) +
                torch::nn::functional::cross_entropy(logits.t(), target));
}

torch::Tensor BatchRetrievalR1(const torch::Tensor& text, const torch::Tensor& motion) {
  // The evaluation's own retrieval (one batch of every row, ties averaged) on the detached means.
  const auto embeddings = [](const torch::Tensor& x) {
    const auto rows = x.detach().to(torch::kDouble).contiguous();
    const double* data = rows.data_ptr<double>();
    return eval::Embeddings{rows.size(0), rows.size(1),
                            std::vector<double>(data, data + rows.numel())};
  };
  const auto scores = eval::Retrieval(embeddings(text), embeddings(motion), 0, 0);
  if (!scores.ok()) throw std::invalid_argument("retrieval_r1: " + scores.status().message());
  return torch::tensor(static_cast<float>(scores->r1));
}

}  // namespace motionpipe::temos
