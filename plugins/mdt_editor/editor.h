// The editing networks (REFERENCE 3.2-3.3), all predicting the clean target x0 from a noisy target:
//
//   mdt   SimMotionEdit's Motion Diffusion Transformer. A condition transformer over [text token;
//         source frames] (post-LN encoder) enhances both and feeds the similarity head (MLP with
//         SiLU -> K classes, or 1 value in regression); DiT blocks with adaLN-Zero run over
//         [enhanced source; separator; noisy target], conditioned on timestep embedding + enhanced
//         text token. Ablations: raw text/motion features instead of enhanced, no text in adaLN.
//   tmed  MotionFix's TMED: one transformer encoder over [timestep; text tokens; source; separator;
//         noisy target].
//   mdm   MDM: one transformer encoder over [timestep + text token; noisy target], no source
//         (MDM-BP is MDM sampled with the unedited body parts kept from the source).
#pragma once

#include <torch/torch.h>

#include <nlohmann/json.hpp>
#include <utility>

#include "../common/text_encoder.h"
#include "../common/transformer.h"
#include "diffusion.h"

namespace motionpipe::mdt {

inline constexpr int64_t kEditFeatureDim = 207;

struct EditorOptions {
  std::string variant = "mdt";  // mdt | tmed | mdm
  int64_t dim = 512, cond_layers = 4, layers = 8, heads = 8, ff = 1024, sim_hidden = 1024;
  double dropout = 0.1;
  // true: each noisy target token also reads the source frame aligned to it (AlignSource; zeros
  // where the source is dropped): target_in takes [x_t, aligned source], as InstructPix2Pix
  // (Brooks et al. 2023) concatenates the source image to the noisy one. Not in the paper, where
  // the source reaches the target tokens only through attention (issue 15: with the source as the
  // prior, the clean estimate's legs lean about half way back to the source, the same in every
  // training seed). mdt and tmed; false (the reference) reads x_t alone.
  bool concat_source = false;
  // true: the MDT's condition transformer reads the text's tokens after its pooled token,
  // [text token; text tokens; source frames], so the enhanced text token and the enhanced source
  // frames attend to the words themselves. The paper pools first (one CLIP sentence embedding,
  // REFERENCE 3.2); ours is the mean of a one-layer learned encoder's tokens, and TMED, which
  // attends to the tokens, edits better once both read the source frame by frame (issue 15). mdt
  // only; false (the reference) reads the pooled token alone.
  bool text_tokens = false;
  // true: the MDT's DiT also reads the text's tokens, [text tokens; source; separator; noisy
  // target] (the condition transformer's outputs for them with text_tokens, their projections
  // without), so that every noisy target token attends to the words in every DiT layer, as TMED's
  // do, instead of meeting the text only as adaLN's per-example scale, shift and gate and through
  // the enhanced source. Not in the paper, whose DiT reads [source; separator; target] (REFERENCE
  // 3.2); issue 15's last untested suspect of why TMED edits better once both read the source
  // frame by frame. mdt only; false (the reference).
  bool dit_text_tokens = false;
  // true: the MDT's DiT also reads the timestep embedding as its first token (TMED's timestep
  // token), beside adaLN's use of it. Not in the paper (DiT conditions on the timestep through
  // adaLN alone); false (the reference). mdt only.
  bool time_token = false;
  // Dropout in the DiT blocks: on the attention weights, the attention's output and the MLP's
  // hidden and output, as in the encoder layers of the condition transformer and of TMED. DiT
  // has none (0, the reference); mdt only.
  double dit_dropout = 0;
  // The MDT's trunk over the noisy target: "dit" (the paper's DiT blocks with adaLN-Zero) or
  // "encoder": TMED's post-LN encoder layers (model.layers, model.dropout) over [timestep token;
  // text tokens; enhanced source; separator; noisy target], no adaLN, so that the MDT differs from
  // TMED only by its condition transformer and auxiliary task. Not in the paper; issue 15's test
  // of whether the DiT block is what edits worse than TMED at this budget. mdt only.
  std::string trunk = "dit";
  // Auxiliary similarity task: classes (K bins of the normalised curve), regression, or none.
  std::string aux = "classes";
  int classes = 3;
  double aux_weight = 0.05;           // the authors' code; the paper writes L = L_aux + L_e (1.0)
  std::vector<double> class_weights;  // default [1, 0, 1] for K = 3 (the authors' code), else ones
  bool enhanced_text = true,
       enhanced_motion = true;  // DiT inputs: condition-transformer outputs or raw projections
  bool adaln_text = true;  // the text token joins the timestep in adaLN (reference default: zeros)
  int64_t diffusion_steps = 300;
  // MDM's velocity loss L_vel (Tevet et al. 2023) on the normalised features' frame-to-
  // frame differences, added with this weight to the x0 loss; 0 (the reference) leaves it out.
  double velocity_weight = 0;
  // MDM's foot-contact loss L_foot (foot_contact.h) in (m/s)^2, added with this weight; 0 (the
  // reference) leaves it out. The frames' rate is `fps` (30, MotionFix's and the corpus's, when 0).
  double foot_contact_weight = 0;
  // MDM's L_vel on the feet through forward kinematics (FootVelocityLoss) in (m/s)^2, added with
  // this weight; 0 (the reference) leaves it out. The frames' rate as for foot_contact.
  double foot_velocity_weight = 0;
  // > 0: a contact head (one Linear on the target tokens' last hidden states) predicts, per frame,
  // which of the four foot joints (left ankle, left toe, right ankle, right toe) the target holds
  // still (ContactLabels), trained by binary cross-entropy with this weight. The edit option
  // `foot_lock: {contacts: predicted}` then plants the feet where the edit's own head says they
  // stand, where the post-process can only guess from height and speed (issue 15: the edits'
  // sliding stance feet move too fast for its speed test). 0 (the reference): no head.
  double contacts_weight = 0;
  // The x0 loss's squared errors on the legs' columns (the left and right leg parts' rotations
  // and joint positions, PartColumns) count this many times in their groups' means. 1 (the
  // reference) weighs every column alike, which gives the legs about 15% of the loss; issue 15
  // measured that the feet slide from the legs' error, systematic across training seeds.
  double leg_weight = 1;
  double snr_shift =
      1;  // > 1: the cosine schedule shifted towards noise (CosineSchedule checks the range)
  // The training steps' density, proportional to t^k (SampleTrainingStep); 0: uniform (the
  // reference). Sampling is unchanged.
  double step_density_power = 0;
  // > 0: the x0 loss of each example weighted by Min-SNR-gamma (MinSnrWeights); 0: unweighted
  // (the reference).
  double min_snr_gamma = 0;
  // How the network's output becomes the x0 estimate. "x0": the output is x0 (REFERENCE 3.2).
  // "edm": Karras et al.'s preconditioning, x0 = c_skip x~ + c_out F, so that near t = 0 the noisy
  // target passes through instead of being rebuilt from the width-d trunk (at d = 128 < 207 the
  // plain head cannot reproduce even a clean target: x0 MSE 0.023 at t = 0 where x_t alone gives
  // 0.0002). The loss is the same x0 MSE either way. Measured at d = 128 (issue 15), "edm" is
  // worse: the skip passes x_t's noise, which the 128-wide trunk cannot cancel at middle steps, and
  // the sampled edits are rough (second differences 200x the target's), so "x0" stays the default.
  //
  // "source": x0 = the source aligned to the target's length (AlignSource) + F, where the source
  // is seen (F alone where it is dropped), and F starts at 0: the untrained editor copies its
  // source and training learns only what the edit changes. Not in the paper: the residual of an
  // edit on its source is the natural prior for editing (the source is the conditional mean of a
  // target before the text is read), and at demo budgets (a few thousand steps against the paper's
  // ~80 k) the plain head never learns to copy (its DDIM edits are as far from their sources as
  // from anything).
  std::string preconditioning = "x0";
  // A gain s(t) per diffusion step and feature column: the estimate adds s(t) (x_t - sqrt(abar_t)
  // prior mean), s starting at the Gaussian (Wiener) optimum for spread sigma_data and corrected
  // by training, so that x_t passes by the trunk where it is nearly clean (the plain head's x0
  // error at t = 0 is 0.023-0.046 where x_t alone gives 0.0002) and the loss sets how much of x_t
  // to trust at each step (not in the paper). Measured (issue 15): it removes that floor but lets
  // the middle steps' noise into the edits, on 207 columns and on 64 components alike.
  bool learned_skip = false;
  double sigma_data = 0.5;  // the normalised features' spread: (x - mean) / (2 std)
  // > 0: the diffusion runs on the first `components` principal components of the normalised
  // 207-d frames (fitted on the training motions with the feature statistics), each scaled to
  // spread sigma_data, instead of on the 207 columns; the network reads and writes those
  // coordinates and the x0 loss is still taken on the decoded 207-d frame. Not in the paper: the
  // 207 columns are redundant (6D rotations, joint positions derived from them, 55 columns the
  // corpus never moves); a linear whitening code, as latent diffusion's but fitted, not trained.
  // Measured at d = 128 with 64 components (issue 15): the x0 error at t = 0 is no lower than
  // with 207 columns (0.048 against 0.040), so the frame's width was not what limited the MDT.
  // 0: the 207 columns (the reference).
  int64_t components = 0;
  // With components: scale each axis to spread sigma_data (true: every axis has the same
  // signal-to-noise ratio at a step), or keep the feature space's scale (false: the 207-column
  // diffusion restricted to the kept axes, the same signal-to-noise ratio per direction).
  bool whiten = true;
  // The frame rate the network works at: training motions and edit sources are brought to it
  // (ToNetworkRate) and edits back to the rate asked for. 0: the data's own (the reference, 30
  // fps in MotionFix). Not in the paper: a step at 10 fps costs about a third of one at 30, and
  // the demo's MDT is limited by its budget (issue 15).
  double fps = 0;
  double drop_text = 0.05, drop_source = 0.05, drop_both = 0.15;  // condition dropout in training
  double guidance_motion = 2, guidance_text = 2;                  // g_m, g_t
  nn::TextEncoderOptions text;
  // A checkpoint whose text encoder (tokenizer and weights) replaces this one's before training, as
  // the paper starts from CLIP: a directory, or "input" (nn::LoadPretrainedTextEncoder); frozen
  // unless freeze_text_encoder is false. Empty: the text encoder learns from the edit texts alone.
  std::string text_encoder_from;
  bool freeze_text_encoder = true;
  static EditorOptions FromJson(const nlohmann::json& j);
  nlohmann::json ToJson() const;
  bool uses_source() const { return variant != "mdm"; }
  int64_t sim_outputs() const { return aux == "regression" ? 1 : classes; }
};

// What the denoiser is conditioned on; drop_* [N] bool remove the text / the source per example.
struct Condition {
  std::vector<std::string> texts;
  torch::Tensor source;          // [Ts, N, 207] normalised (undefined for mdm)
  torch::Tensor source_padding;  // [N, Ts] true = padding
  torch::Tensor drop_text, drop_source;
};

// The source [Ts, N, C] resampled to each target's length [Tt, N, C]: target frame i of an
// L_t-frame target takes source frame floor(i L_s / L_t), the centre of the similarity curve's
// window (REFERENCE 3.1). Lengths come from the paddings (true = padding).
torch::Tensor AlignSource(const torch::Tensor& source, const torch::Tensor& source_padding,
                          const torch::Tensor& target_padding);

// DiT's MLP activation, GELU's tanh approximation (REFERENCE: "tanh-GELU MLP"). A bf16 input takes
// the fused kernel (nn::GeluTanhBf16): the float32 function rounded once, nearer the exact values
// than LibTorch 1.13's bf16 kernel (which rounds its intermediates and took a sixth of a bf16
// training step of the demo's MDT) and cheaper than LibTorch's float32 kernel with both
// conversions (bench/mdt_bench prints both).
torch::Tensor GeluTanh(const torch::Tensor& x);

// adaLN-Zero around a DiT sub-layer (REFERENCE: "LayerNorm without affine", shift/scale/gate):
// Modulate is LN(x) (1 + scale) + shift (eps 1e-6), GatedResidual is x + gate y. For a float32
// stream under bf16 autocast (bf16 modulation and sub-layer output) they take the fused kernels
// (nn::ModulatedLayerNormBf16, nn::GatedResidualBf16: one pass each way, the float32 expression
// rounded once, Modulate's output in the bf16 the next linear would cast it to); otherwise
// LibTorch's operators.
torch::Tensor Modulate(const torch::Tensor& x, const torch::Tensor& scale,
                       const torch::Tensor& shift);
torch::Tensor GatedResidual(const torch::Tensor& x, const torch::Tensor& gate,
                            const torch::Tensor& y);

struct Prediction {
  torch::Tensor x0;          // [Tt, N, diffusion_dim()]: 207 columns or `components` coordinates
  torch::Tensor similarity;  // mdt: [N, Ts, K] logits (or [N, Ts] regression); else undefined
  torch::Tensor contacts;    // loss.contacts > 0: [Tt, N, 4] logits (ContactLabels' order)
};

// A DiT block with adaLN-Zero: shift/scale/gate for attention and MLP from SiLU -> Linear(d, 6d),
// zero-initialised, so that the block starts as the identity; LayerNorms without affine; tanh-GELU
// MLP.
class DiTBlockImpl : public torch::nn::Module {
 public:
  DiTBlockImpl(int64_t dim, int64_t heads, int64_t ff, double dropout = 0);
  // x [T, N, d]; silu_c = SiLU(condition) [N, d] (the caller computes it once for every block).
  torch::Tensor forward(const torch::Tensor& x, const torch::Tensor& silu_c,
                        const torch::Tensor& padding);

 private:
  nn::SelfAttention attention_{nullptr};
  torch::nn::Linear fc1_{nullptr}, fc2_{nullptr}, modulation_{nullptr};
  double dropout_;
};
TORCH_MODULE(DiTBlock);

class EditorNetImpl : public torch::nn::Module {
 public:
  explicit EditorNetImpl(const EditorOptions& o);
  // xt [Tt, N, diffusion_dim()] at steps t [N], target_padding [N, Tt]. The x0 estimate in the
  // same coordinates, after the preconditioning of the options.
  Prediction forward(const torch::Tensor& xt, const torch::Tensor& t,
                     const torch::Tensor& target_padding, const Condition& c);
  nn::TextEncoder text_encoder() const { return text_encoder_; }
  const EditorOptions& options() const { return o_; }
  // The coordinates the diffusion runs on (options.components): 207 normalised feature columns
  // [..., 207] <-> [..., diffusion_dim()]; the identity when components is 0.
  int64_t diffusion_dim() const;
  torch::Tensor Encode(const torch::Tensor& x) const;
  torch::Tensor Decode(const torch::Tensor& z) const;
  // Sets the frame code from the covariance [207, 207] of normalised training frames
  // (PrincipalFrameBasis); returns the share of the variance the kept components explain.
  double FitFrameBasis(const torch::Tensor& covariance);
  // The two terms of the MDT's adaLN condition (DiT: timestep embedding + class embedding): the
  // timestep embedding [N, d] and the text token's contribution [N, d] (text_cond of the text
  // token).
  torch::Tensor TimeEmbedding(const torch::Tensor& t);
  torch::Tensor TextCondition(const torch::Tensor& text);

  // The pieces of a denoiser's input sequence, each with its own learned segment embedding.
  enum Segment : int64_t { kTime = 0, kText, kSource, kSeparator, kTarget, kSegments };

 private:
  // Pooled text [N, dim] (zeros where dropped) and token features [L, N, dim] with padding.
  std::pair<torch::Tensor, nn::TextFeatures> EncodeText(const Condition& c);
  // x [L, N, d] + the sinusoid of each token's index within its own segment + the segment's
  // embedding: positions that do not depend on the other examples of the batch (source frame i and
  // target frame i share the sinusoid of i, which also makes copying a frame an easy alignment).
  torch::Tensor Place(const torch::Tensor& x, Segment segment) const;
  // The source aligned to the target's frames in the diffusion's coordinates, zeros where it is
  // dropped [Tt, N, diffusion_dim()]: the source prior's base and concat_source's second half.
  torch::Tensor AlignedSource(const torch::Tensor& target_padding, const Condition& c) const;
  // The noisy target's tokens [Tt, N, d] before placing: target_in of x_t (with concat_source, of
  // [x_t, aligned]; `aligned` is AlignedSource's, undefined without concat_source).
  torch::Tensor TargetTokens(const torch::Tensor& xt, const torch::Tensor& aligned);
  Prediction ForwardMdt(const torch::Tensor& xt, const torch::Tensor& t,
                        const torch::Tensor& target_padding, const Condition& c,
                        const torch::Tensor& aligned);
  Prediction ForwardEncoder(const torch::Tensor& xt, const torch::Tensor& t,
                            const torch::Tensor& target_padding, const Condition& c,
                            const torch::Tensor& aligned);

  EditorOptions o_;
  CosineSchedule schedule_;
  torch::Tensor skip_;                 // learned_skip: [steps, diffusion_dim()]
  torch::Tensor basis_, basis_scale_;  // components > 0: [207, k] orthonormal, [k] spreads / sd
  nn::TextEncoder text_encoder_{nullptr};
  torch::nn::Linear text_proj_{nullptr}, source_in_{nullptr}, target_in_{nullptr}, out_{nullptr};
  torch::nn::Linear contact_out_{nullptr};  // loss.contacts > 0: the contact head
  torch::nn::Sequential time_mlp_{nullptr}, sim_head_{nullptr};
  nn::Encoder condition_{nullptr}, encoder_{nullptr};
  torch::nn::ModuleList blocks_{nullptr};
  torch::nn::Linear final_modulation_{nullptr}, text_cond_{nullptr};
  torch::Tensor separator_, segments_;
};
TORCH_MODULE(EditorNet);

// The principal axes of frames with this covariance [C, C]: the `components` eigenvectors of the
// largest eigenvalues as columns [C, k] (each with its largest entry positive, so the basis does
// not depend on the solver's signs), and their spreads sqrt(lambda) / sigma_data [k], so that
// z = x B / scale has spread sigma_data along each axis. `explained` receives the kept share of
// the total variance.
std::pair<torch::Tensor, torch::Tensor> PrincipalFrameBasis(const torch::Tensor& covariance,
                                                            int64_t components, double sigma_data,
                                                            double* explained);

// Masked MSE on x0 averaged per feature group (the 207-d layout's five), then over the groups, per
// example, then over the examples (each times `weight` [N] when given). prediction/target
// [T, N, 207], padding [N, T]; `columns` [207], when given, multiplies each column's squared
// errors before the groups' means.
torch::Tensor GroupedMaskedMse(const torch::Tensor& prediction, const torch::Tensor& target,
                               const torch::Tensor& padding, const torch::Tensor& weight = {},
                               const torch::Tensor& columns = {});

// The x0 loss's column weights [207]: `leg_weight` on the legs' columns (PartColumns' left and
// right legs), 1 elsewhere.
torch::Tensor LegColumnWeights(double leg_weight);

// GroupedMaskedMse of the first differences over time (frames t and t - 1 both real).
torch::Tensor VelocityMse(const torch::Tensor& prediction, const torch::Tensor& target,
                          const torch::Tensor& padding);

// The auxiliary similarity loss (SimMotionEdit eq. 11) on the frames that count: a curve exists
// (classes >= 0), the frame is real (not padding) and the example's source was not dropped.
// classes mode: cross-entropy with the class weights, averaged by weight; regression: MSE of the
// sigmoid against S^N. Returns "aux" (and "aux_accuracy" for classes).
std::map<std::string, torch::Tensor> SimilarityLoss(
    const torch::Tensor& prediction, const torch::Tensor& classes, const torch::Tensor& similarity,
    const torch::Tensor& source_padding, const torch::Tensor& drop_source, const EditorOptions& o);

// Columns of the 207-d feature that belong to each body part (SMPL-22 parts; global = pelvis
// velocity, orientation, heading change): [6, 207] bool.
torch::Tensor PartColumns();

}  // namespace motionpipe::mdt
