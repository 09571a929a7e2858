// TEMOS (REFERENCE 4.5) as SINC extends it: a text VAE encoder and a motion VAE encoder
// (transformer encoders with two learned tokens whose outputs are mu and logvar), and a transformer
// decoder over positional queries of the wanted duration with the latent as memory.
//
// Losses with the reference weights: smooth-L1 reconstruction from the text branch and from the
// motion branch, KL(text || motion), KL(motion || text), KL(text || N(0, I)), KL(motion || N(0, I))
// (1e-5 each), smooth-L1 between the two latents (1e-5). With `contrastive` > 0 it is TMR
// (REFERENCE 5): InfoNCE on the cosine of the two means, temperature 0.1, symmetric, near-duplicate
// texts masked out.
#pragma once

#include <torch/torch.h>

#include <nlohmann/json.hpp>

#include "../common/text_encoder.h"

namespace motionpipe::temos {

inline constexpr int64_t kFeatureDim = 135;

struct TemosOptions {
  int64_t latent = 256;
  int64_t layers = 6;
  int64_t heads = 4;  // REFERENCE lists 6, which does not divide 256; TEMOS's code uses 4
  int64_t ff = 1024;
  double dropout = 0.1;
  double kl_weight = 1e-5;
  double latent_weight = 1e-5;
  // Weight of the text branch's reconstruction (the reference's 1). 0 with latent_weight 0 leaves
  // a motion VAE beside a text encoder that only the KL terms reach: an ablation (issue 15: does
  // decoding the text's latent, which cannot know a walk's phase, average the gait out?).
  double text_reconstruction = 1;
  // Scale of the reparameterisation noise in training (the reference's 1: z = mu + sigma * eps);
  // 0 decodes the means (an autoencoder): an ablation (issue 15: does the posterior's noise, not
  // small beside the means' spread, average the gait out?).
  double latent_noise = 1;
  // How the decoder's frames see the latent: "memory" (TEMOS: z is the cross-attention's one memory
  // token, so it reaches every frame as the same added vector) or "film" (also, before every layer,
  // z scales and shifts the frames' queries, zero-initialised: a gait's phase is a product of z and
  // the frame's position, which an added vector gives only through the feed-forward layers; issue
  // 15).
  std::string decoder = "memory";
  // Weight of a reconstruction term on the features' frame-to-frame differences (0: the
  // reference's losses alone). Issue 15: the legs' within-motion part (the gait) is a small share
  // of those features' variance beside the between-motion part (posture); the differences are the
  // gait alone. Measured: at 1 the legs come out stiller, not livelier (README "What does: views of
  // each motion"); an ablation, no shipped config uses it.
  double velocity_weight = 0;
  double contrastive = 0;  // TMR: 0.1
  double temperature = 0.1;
  double duplicate_threshold = 0.6;
  bool separate_texts = false;  // SINC-STE: each action text encoded apart, joined by a separator
  nn::TextEncoderOptions text;
  static TemosOptions FromJson(const nlohmann::json& j);
  nlohmann::json ToJson() const;
};

// An ACTOR-style VAE encoder: [mu token; logvar token; inputs] + positions -> transformer.
class VaeEncoderImpl : public torch::nn::Module {
 public:
  VaeEncoderImpl(int64_t input_dim, const TemosOptions& o);
  // x [L, N, input_dim], padding [N, L] (true = pad) -> mu, logvar [N, latent]
  std::pair<torch::Tensor, torch::Tensor> forward(const torch::Tensor& x,
                                                  const torch::Tensor& padding);

 private:
  int64_t latent_;
  torch::nn::Linear project_{nullptr};
  torch::Tensor mu_token_, logvar_token_;
  nn::Encoder encoder_{nullptr};
};
TORCH_MODULE(VaeEncoder);

class DecoderImpl : public torch::nn::Module {
 public:
  explicit DecoderImpl(const TemosOptions& o);
  // z [N, latent], lengths -> features [T, N, 135] (T = max length), padded frames zeroed
  torch::Tensor forward(const torch::Tensor& z, const torch::Tensor& padding);

 private:
  int64_t latent_, layers_;
  nn::OneTokenDecoder decoder_{nullptr};
  torch::nn::Linear out_{nullptr};
  torch::nn::Linear film_{nullptr};  // decoder "film": z -> [layers, 2 * latent]
};
TORCH_MODULE(Decoder);

struct Distribution {
  torch::Tensor mu, logvar, z;
};

class TemosImpl : public torch::nn::Module {
 public:
  explicit TemosImpl(const TemosOptions& o);
  // Texts of each example (one, or the actions for SINC-STE).
  Distribution EncodeText(const std::vector<std::vector<std::string>>& texts, bool sample);
  Distribution EncodeMotion(const torch::Tensor& features, const torch::Tensor& padding,
                            bool sample);
  torch::Tensor Decode(const torch::Tensor& z, const torch::Tensor& padding) {
    return decoder_->forward(z, padding);
  }
  // features [T, N, 135] (normalised), padding [N, T]: every loss term and "loss", and
  // "retrieval_r1" (BatchRetrievalR1 of the two encoders' means; logged, not a loss).
  // example_seeds [N] (optional): the seed of each example's reparameterisation noise.
  std::map<std::string, torch::Tensor> Losses(const std::vector<std::vector<std::string>>& texts,
                                              const torch::Tensor& features,
                                              const torch::Tensor& padding,
                                              const torch::Tensor& example_seeds = {});
  nn::TextEncoder text_encoder() const { return text_encoder_; }
  const TemosOptions& options() const { return options_; }

 private:
  TemosOptions options_;
  nn::TextEncoder text_encoder_{nullptr};
  VaeEncoder text_vae_{nullptr}, motion_vae_{nullptr};
  Decoder decoder_{nullptr};
};
TORCH_MODULE(Temos);

// Per-example noise [rows, N, latent] from each example's seed.
torch::Tensor ExampleNoise(const torch::Tensor& seeds, int64_t rows, int64_t latent);
// Smooth-L1 averaged over each example's unpadded frames, then over the examples. prediction/target
// [T, N, D], padding [N, T].
torch::Tensor MaskedSmoothL1(const torch::Tensor& prediction, const torch::Tensor& target,
                             const torch::Tensor& padding);
// MaskedSmoothL1 of the frame-to-frame differences (pairs of unpadded frames), both divided by the
// root mean square of the batch's target differences (a detached scalar), so that the term weighs
// the same whatever the frame rate.
torch::Tensor MaskedVelocitySmoothL1(const torch::Tensor& prediction, const torch::Tensor& target,
                                     const torch::Tensor& padding);
// KL(q || p) of diagonal Gaussians, averaged over the batch and the latent dimensions.
torch::Tensor KlDivergence(const torch::Tensor& mu_q, const torch::Tensor& logvar_q,
                           const torch::Tensor& mu_p, const torch::Tensor& logvar_p);
// Lexical near-duplicates [N, N] bool: the cosine of two examples' bag-of-words counts (their texts
// joined, lower case) above `threshold`, the diagonal false. TMR masks negatives whose texts mean
// the same; without a sentence encoder offline, word overlap stands in.
torch::Tensor NearDuplicates(const std::vector<std::vector<std::string>>& texts, double threshold);
// Symmetric InfoNCE on cosine similarities / temperature; pairs whose texts are near-duplicates
// (duplicate[i][j] true, i != j) are removed from the negatives.
torch::Tensor InfoNce(const torch::Tensor& a, const torch::Tensor& b, double temperature,
                      const torch::Tensor& duplicate);
// Text-to-motion R@1 in percent within a batch: the share of rows of `text` [N, D] whose own row of
// `motion` is strictly the nearest by cosine (ties averaged, so a tie is a miss): the evaluation's
// eval::Retrieval on the batch at hand, in double whatever the inputs' dtype; no gradient. A
// training run's text-specificity over time.
torch::Tensor BatchRetrievalR1(const torch::Tensor& text, const torch::Tensor& motion);

}  // namespace motionpipe::temos
