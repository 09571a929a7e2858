#include "editor.h"

#include <algorithm>
#include <cmath>

#include "../common/fused.h"
#include "foot_contact.h"
#include "motionpipe/features/motionfix207.h"
#include "motionpipe/skeleton/skeleton.h"

namespace motionpipe::mdt {

namespace {

torch::Tensor AnyPadding(int64_t n, int64_t length) {
  return torch::zeros({n, length}, torch::kBool);
}

// A key this version does not know is an error naming it: a misspelt or newer option must not be
// ignored silently (an experiment once trained without the option it was written to measure).
void RequireKnownKeys(const nlohmann::json& j, const std::string& where,
                      const std::vector<std::string>& known) {
  if (!j.is_object()) return;
  for (const auto& [key, value] : j.items()) {
    if (std::find(known.begin(), known.end(), key) != known.end()) continue;
    std::string list;
    for (const auto& k : known) list += (list.empty() ? "" : ", ") + k;
    throw std::invalid_argument(where + key + ": unknown key (known: " + list + ")");
  }
}

}  // namespace

EditorOptions EditorOptions::FromJson(const nlohmann::json& j) {
  RequireKnownKeys(j, "",
                   {"variant", "model", "aux", "features", "adaln_text", "diffusion", "loss",
                    "text_encoder_from", "freeze_text_encoder", "fps"});
  RequireKnownKeys(
      j.value("model", nlohmann::json::object()), "model.",
      {"dim", "cond_layers", "layers", "heads", "ff", "sim_hidden", "dropout", "text_encoder",
       "concat_source", "text_tokens", "dit_text_tokens", "time_token", "dit_dropout", "trunk"});
  RequireKnownKeys(j.value("aux", nlohmann::json::object()), "aux.",
                   {"mode", "classes", "weight", "class_weights"});
  RequireKnownKeys(j.value("features", nlohmann::json::object()), "features.", {"text", "motion"});
  RequireKnownKeys(j.value("loss", nlohmann::json::object()), "loss.",
                   {"velocity", "foot_contact", "foot_velocity", "contacts", "legs"});
  RequireKnownKeys(j.value("diffusion", nlohmann::json::object()), "diffusion.",
                   {"steps", "drop_text", "drop_source", "drop_both", "guidance_motion",
                    "guidance_text", "preconditioning", "sigma_data", "snr_shift",
                    "step_density_power", "learned_skip", "components", "whiten", "min_snr_gamma"});
  EditorOptions o;
  o.variant = j.value("variant", o.variant);
  if (o.variant != "mdt" && o.variant != "tmed" && o.variant != "mdm") {
    throw std::invalid_argument("variant must be mdt, tmed or mdm (got '" + o.variant + "')");
  }
  const nlohmann::json m = j.value("model", nlohmann::json::object());
  o.dim = m.value("dim", o.dim);
  o.cond_layers = m.value("cond_layers", o.cond_layers);
  o.layers = m.value("layers", o.layers);
  o.heads = m.value("heads", o.variant == "mdt" ? o.heads : int64_t{4});
  o.ff = m.value("ff", o.ff);
  o.sim_hidden = m.value("sim_hidden", o.sim_hidden);
  o.dropout = m.value("dropout", o.dropout);
  o.concat_source = m.value("concat_source", o.concat_source);
  o.text_tokens = m.value("text_tokens", o.text_tokens);
  if (o.text_tokens && o.variant != "mdt")
    throw std::invalid_argument(
        "model.text_tokens: only the mdt variant has a condition transformer (TMED reads the "
        "tokens already; got variant '" +
        o.variant + "')");
  o.dit_text_tokens = m.value("dit_text_tokens", o.dit_text_tokens);
  o.time_token = m.value("time_token", o.time_token);
  o.dit_dropout = m.value("dit_dropout", o.dit_dropout);
  o.trunk = m.value("trunk", o.trunk);
  if (o.trunk != "dit" && o.trunk != "encoder")
    throw std::invalid_argument("model.trunk must be dit or encoder (got '" + o.trunk + "')");
  if ((o.dit_text_tokens || o.time_token || o.dit_dropout != 0 || o.trunk != "dit") &&
      o.variant != "mdt")
    throw std::invalid_argument(
        "model.dit_text_tokens, time_token, dit_dropout and trunk: only the mdt variant has a DiT "
        "(got variant '" +
        o.variant + "')");
  if (o.dit_dropout < 0 || o.dit_dropout >= 1)
    throw std::invalid_argument("model.dit_dropout must be in [0, 1)");
  const nlohmann::json a = j.value("aux", nlohmann::json::object());
  o.aux = a.value("mode", o.variant == "mdt" ? o.aux : std::string("none"));
  o.classes = a.value("classes", o.classes);
  o.aux_weight = a.value("weight", o.aux_weight);
  if (o.aux != "classes" && o.aux != "regression" && o.aux != "none")
    throw std::invalid_argument("aux.mode must be classes, regression or none");
  if (o.aux != "none" && o.variant != "mdt")
    throw std::invalid_argument("the similarity task belongs to the mdt variant (aux.mode: none)");
  if (o.classes < 2 || o.classes > 64)
    throw std::invalid_argument("aux.classes must be in [2, 64]");
  o.class_weights = a.value("class_weights", std::vector<double>());
  if (o.class_weights.empty()) {
    o.class_weights.assign(static_cast<size_t>(o.classes), 1.0);
    if (o.classes == 3) o.class_weights = {1, 0, 1};
  }
  if (static_cast<int>(o.class_weights.size()) != o.classes)
    throw std::invalid_argument("aux.class_weights needs one weight per class");
  const nlohmann::json f = j.value("features", nlohmann::json::object());
  const std::string text = f.value("text", std::string("enhanced")),
                    motion = f.value("motion", std::string("enhanced"));
  if ((text != "enhanced" && text != "raw") || (motion != "enhanced" && motion != "raw")) {
    throw std::invalid_argument("features.text and features.motion must be enhanced or raw");
  }
  o.enhanced_text = text == "enhanced";
  o.enhanced_motion = motion == "enhanced";
  o.adaln_text = j.value("adaln_text", o.adaln_text);
  o.fps = j.value("fps", o.fps);
  if (!(o.fps >= 0 && o.fps <= 1000))
    throw std::invalid_argument("fps must be in [0, 1000] (0: the data's own rate)");
  const nlohmann::json d = j.value("diffusion", nlohmann::json::object());
  o.diffusion_steps = d.value("steps", o.diffusion_steps);
  o.snr_shift = d.value("snr_shift", o.snr_shift);
  o.step_density_power = d.value("step_density_power", o.step_density_power);
  if (!(o.step_density_power >= 0 && o.step_density_power <= 10))
    throw std::invalid_argument("diffusion.step_density_power must be in [0, 10]");
  o.min_snr_gamma = d.value("min_snr_gamma", o.min_snr_gamma);
  if (!(o.min_snr_gamma >= 0)) throw std::invalid_argument("diffusion.min_snr_gamma must be >= 0");
  o.velocity_weight =
      j.value("loss", nlohmann::json::object()).value("velocity", o.velocity_weight);
  if (!(o.velocity_weight >= 0)) throw std::invalid_argument("loss.velocity must be >= 0");
  o.foot_contact_weight =
      j.value("loss", nlohmann::json::object()).value("foot_contact", o.foot_contact_weight);
  if (!(o.foot_contact_weight >= 0)) throw std::invalid_argument("loss.foot_contact must be >= 0");
  o.foot_velocity_weight =
      j.value("loss", nlohmann::json::object()).value("foot_velocity", o.foot_velocity_weight);
  if (!(o.foot_velocity_weight >= 0))
    throw std::invalid_argument("loss.foot_velocity must be >= 0");
  o.contacts_weight =
      j.value("loss", nlohmann::json::object()).value("contacts", o.contacts_weight);
  if (!(o.contacts_weight >= 0)) throw std::invalid_argument("loss.contacts must be >= 0");
  o.leg_weight = j.value("loss", nlohmann::json::object()).value("legs", o.leg_weight);
  if (!(o.leg_weight > 0)) throw std::invalid_argument("loss.legs must be > 0");
  o.drop_text = d.value("drop_text", o.variant == "mdm" ? 0.1 : o.drop_text);
  o.drop_source = d.value("drop_source", o.variant == "mdm" ? 0.0 : o.drop_source);
  o.drop_both = d.value("drop_both", o.variant == "mdm" ? 0.0 : o.drop_both);
  o.preconditioning = d.value("preconditioning", o.preconditioning);
  if (o.preconditioning != "x0" && o.preconditioning != "edm" && o.preconditioning != "source")
    throw std::invalid_argument("diffusion.preconditioning must be x0, edm or source");
  if (o.preconditioning == "source" && !o.uses_source())
    throw std::invalid_argument(
        "diffusion.preconditioning source needs a variant that sees the "
        "source (mdt or tmed)");
  o.sigma_data = d.value("sigma_data", o.sigma_data);
  o.learned_skip = d.value("learned_skip", o.learned_skip);
  if (!(o.sigma_data > 0)) throw std::invalid_argument("diffusion.sigma_data must be positive");
  o.components = d.value("components", o.components);
  if (o.components < 0 || o.components > kEditFeatureDim)
    throw std::invalid_argument("diffusion.components must be in [0, 207] (0: the 207 columns)");
  o.whiten = d.value("whiten", o.whiten);
  o.guidance_motion = d.value("guidance_motion", o.guidance_motion);
  o.guidance_text = d.value("guidance_text", o.variant == "mdm" ? 2.5 : o.guidance_text);
  if (o.drop_text + o.drop_source + o.drop_both > 1)
    throw std::invalid_argument("diffusion: the condition dropout probabilities sum above 1");
  nlohmann::json t = m.value("text_encoder", nlohmann::json::object());
  if (!t.contains("dim")) t["dim"] = std::min<int64_t>(o.dim, 256);
  if (!t.contains("dropout")) t["dropout"] = o.dropout;
  o.text = nn::TextEncoderOptions::FromJson(t);
  o.text_encoder_from = j.value("text_encoder_from", o.text_encoder_from);
  o.freeze_text_encoder = j.value("freeze_text_encoder", o.freeze_text_encoder);
  if (o.dim % o.heads != 0)
    throw std::invalid_argument("model.dim must be divisible by model.heads");
  return o;
}

nlohmann::json EditorOptions::ToJson() const {
  return {{"variant", variant},
          {"model",
           {{"dim", dim},
            {"cond_layers", cond_layers},
            {"layers", layers},
            {"heads", heads},
            {"ff", ff},
            {"sim_hidden", sim_hidden},
            {"dropout", dropout},
            {"concat_source", concat_source},
            {"text_tokens", text_tokens},
            {"dit_text_tokens", dit_text_tokens},
            {"time_token", time_token},
            {"dit_dropout", dit_dropout},
            {"trunk", trunk},
            {"text_encoder", text.ToJson()}}},
          {"aux",
           {{"mode", aux},
            {"classes", classes},
            {"weight", aux_weight},
            {"class_weights", class_weights}}},
          {"features",
           {{"text", enhanced_text ? "enhanced" : "raw"},
            {"motion", enhanced_motion ? "enhanced" : "raw"}}},
          {"adaln_text", adaln_text},
          {"fps", fps},
          {"text_encoder_from", text_encoder_from},
          {"freeze_text_encoder", freeze_text_encoder},
          {"loss",
           {{"velocity", velocity_weight},
            {"foot_contact", foot_contact_weight},
            {"foot_velocity", foot_velocity_weight},
            {"contacts", contacts_weight},
            {"legs", leg_weight}}},
          {"diffusion",
           {{"steps", diffusion_steps},
            {"drop_text", drop_text},
            {"drop_source", drop_source},
            {"drop_both", drop_both},
            {"guidance_motion", guidance_motion},
            {"guidance_text", guidance_text},
            {"preconditioning", preconditioning},
            {"learned_skip", learned_skip},
            {"components", components},
            {"whiten", whiten},
            {"sigma_data", sigma_data},
            {"snr_shift", snr_shift},
            {"step_density_power", step_density_power},
            {"min_snr_gamma", min_snr_gamma}}}};
}

torch::Tensor GeluTanh(const torch::Tensor& x) {
  if (x.scalar_type() == torch::kBFloat16) return nn::GeluTanhBf16(x);
  if (x.scalar_type() == torch::kFloat) return nn::GeluTanhFloat32(x);
  return torch::gelu(x, "tanh");
}

torch::Tensor Modulate(const torch::Tensor& x, const torch::Tensor& scale,
                       const torch::Tensor& shift) {
  if (x.scalar_type() == torch::kFloat && scale.scalar_type() == torch::kBFloat16 &&
      shift.scalar_type() == torch::kBFloat16)
    return nn::ModulatedLayerNormBf16(x, scale, shift, 1e-6);
  if (x.scalar_type() == torch::kFloat && scale.scalar_type() == torch::kFloat &&
      shift.scalar_type() == torch::kFloat)
    return nn::ModulatedLayerNormFloat32(x, scale, shift, 1e-6);
  return torch::layer_norm(x, {x.size(-1)}, {}, {}, 1e-6) * (1 + scale) + shift;
}

torch::Tensor GatedResidual(const torch::Tensor& x, const torch::Tensor& gate,
                            const torch::Tensor& y) {
  if (x.scalar_type() == torch::kFloat && gate.scalar_type() == torch::kBFloat16 &&
      y.scalar_type() == torch::kBFloat16)
    return nn::GatedResidualBf16(x, gate, y);
  if (x.scalar_type() == torch::kFloat && gate.scalar_type() == torch::kFloat &&
      y.scalar_type() == torch::kFloat)
    return nn::GatedResidualFloat32(x, gate, y);
  return x + gate * y;
}

DiTBlockImpl::DiTBlockImpl(int64_t dim, int64_t heads, int64_t ff, double dropout)
    : dropout_(dropout) {
  attention_ = register_module("attn", nn::SelfAttention(dim, heads, dropout));
  fc1_ = register_module("fc1", torch::nn::Linear(dim, ff));
  fc2_ = register_module("fc2", torch::nn::Linear(ff, dim));
  modulation_ = register_module("adaLN_modulation", torch::nn::Linear(dim, 6 * dim));
  torch::NoGradGuard no_grad;
  modulation_->weight.zero_();  // adaLN-Zero: every gate starts at 0, the block at the identity
  modulation_->bias.zero_();
}

torch::Tensor DiTBlockImpl::forward(const torch::Tensor& x, const torch::Tensor& silu_c,
                                    const torch::Tensor& padding) {
  const auto m = nn::ApplyLinear(modulation_, silu_c).unsqueeze(0).chunk(6, 2);  // each [1, N, d]
  const bool train = is_training();
  auto h = GatedResidual(
      x, m[2], nn::Dropout(attention_->forward(Modulate(x, m[1], m[0]), padding), dropout_, train));
  const auto mlp = nn::ApplyLinear(
      fc2_, nn::Dropout(GeluTanh(nn::ApplyLinear(fc1_, Modulate(h, m[4], m[3]))), dropout_, train));
  return GatedResidual(h, m[5], nn::Dropout(mlp, dropout_, train));
}

EditorNetImpl::EditorNetImpl(const EditorOptions& o)
    : o_(o), schedule_(o.diffusion_steps, o.snr_shift) {
  const nn::TransformerOptions layer{o.dim, o.heads, o.ff, o.layers, o.dropout};
  text_encoder_ = register_module("text_encoder", nn::TextEncoder(o.text));
  text_proj_ = register_module("text_proj", torch::nn::Linear(o.text.dim, o.dim));
  if (o.components > 0) {
    // The identity's first columns until FitFrameBasis (or a checkpoint) sets the code.
    basis_ = register_buffer("frame_basis", torch::eye(kEditFeatureDim).narrow(1, 0, o.components));
    basis_scale_ = register_buffer("frame_scale", torch::ones({o.components}));
  }
  if (o.concat_source && !o.uses_source())
    throw std::invalid_argument(
        "model.concat_source needs a variant that sees the source (mdt or tmed)");
  target_in_ = register_module(
      "target_in", torch::nn::Linear((o.concat_source ? 2 : 1) * diffusion_dim(), o.dim));
  out_ = register_module("out", torch::nn::Linear(o.dim, diffusion_dim()));
  if (o.contacts_weight > 0)
    contact_out_ = register_module("contact_out", torch::nn::Linear(o.dim, kContactJoints));
  time_mlp_ = register_module(
      "time_mlp", torch::nn::Sequential(torch::nn::Linear(256, o.dim), torch::nn::SiLU(),
                                        torch::nn::Linear(o.dim, o.dim)));
  if (o.uses_source()) {
    source_in_ = register_module("source_in", torch::nn::Linear(kEditFeatureDim, o.dim));
    separator_ = register_parameter("separator", torch::randn({o.dim}) * 0.02);
  }
  segments_ = register_parameter("segments", torch::randn({kSegments, o.dim}) * 0.02);
  if (o.learned_skip) {
    if (o.preconditioning == "edm")
      throw std::invalid_argument("diffusion.learned_skip replaces edm's fixed skip: not both");
    skip_ = register_parameter("skip", torch::zeros({o.diffusion_steps, diffusion_dim()}));
  }
  if (o.preconditioning == "source" || o.learned_skip) {
    // The untrained network adds nothing to the aligned source (its edit is the copy) or to the
    // skip's Wiener estimate.
    torch::NoGradGuard no_grad;
    out_->weight.zero_();
    out_->bias.zero_();
  }
  if (o.variant == "mdt") {
    condition_ = register_module("condition", nn::Encoder(nn::TransformerOptions{
                                                  o.dim, o.heads, o.ff, o.cond_layers, o.dropout}));
    sim_head_ = register_module(
        "sim_head",
        torch::nn::Sequential(torch::nn::Linear(o.dim, o.sim_hidden), torch::nn::SiLU(),
                              torch::nn::Linear(o.sim_hidden, o.sim_hidden), torch::nn::SiLU(),
                              torch::nn::Linear(o.sim_hidden, o.sim_outputs())));
    if (o.trunk == "encoder") {  // TMED's layers over the noisy target; no adaLN
      encoder_ = register_module("encoder", nn::Encoder(layer));
      return;
    }
    blocks_ = register_module("blocks", torch::nn::ModuleList());
    for (int64_t k = 0; k < o.layers; ++k)
      blocks_->push_back(DiTBlock(o.dim, o.heads, o.ff, o.dit_dropout));
    final_modulation_ = register_module("final_modulation", torch::nn::Linear(o.dim, 2 * o.dim));
    // The text token is post-LayerNorm (entries of unit spread, norm about sqrt(d)); the timestep
    // embedding's norm is a unit or two. DiT's class embeddings start at N(0, 0.02): text_cond's
    // weights N(0, 0.02 / sqrt(d)) give the text term that same start (entries of spread 0.02), so
    // it adds to the timestep instead of drowning it, and grows as training asks.
    text_cond_ = register_module("text_cond", torch::nn::Linear(o.dim, o.dim));
    torch::NoGradGuard no_grad;
    final_modulation_->weight.zero_();
    final_modulation_->bias.zero_();
    text_cond_->weight.normal_(0.0, 0.02 / std::sqrt(static_cast<double>(o.dim)));
    text_cond_->bias.zero_();
  } else {
    encoder_ = register_module("encoder", nn::Encoder(layer));
  }
}

std::pair<torch::Tensor, nn::TextFeatures> EditorNetImpl::EncodeText(const Condition& c) {
  nn::TextFeatures f = text_encoder_->forward(c.texts);
  auto tokens = nn::ApplyLinear(text_proj_, f.tokens);                            // [L, N, d]
  const auto keep = f.padding.logical_not().t().unsqueeze(2).to(tokens.dtype());  // [L, N, 1]
  auto pooled = (tokens * keep).sum(0) / keep.sum(0).clamp_min(1.0);              // [N, d]
  if (c.drop_text.defined()) {
    const auto drop = c.drop_text.view({-1, 1}).to(tokens.dtype());
    pooled = pooled * (1 - drop);
    tokens = tokens * (1 - drop.unsqueeze(0));
  }
  return {pooled, {tokens, f.padding}};
}

torch::Tensor EditorNetImpl::TimeEmbedding(const torch::Tensor& t) {
  return nn::ApplySequential(time_mlp_, TimestepEmbedding(t, 256));
}

torch::Tensor EditorNetImpl::TextCondition(const torch::Tensor& text) {
  if (!text_cond_)
    throw std::logic_error("TextCondition: only the mdt variant conditions adaLN on text");
  return nn::ApplyLinear(text_cond_, text);
}

torch::Tensor EditorNetImpl::Place(const torch::Tensor& x, Segment segment) const {
  return x + nn::PositionalEncoding(x.size(0), o_.dim) + segments_[segment].view({1, 1, -1});
}

Prediction EditorNetImpl::forward(const torch::Tensor& xt, const torch::Tensor& t,
                                  const torch::Tensor& target_padding, const Condition& c) {
  // One alignment serves both of the source's uses: the prior's base and the concatenated input.
  const torch::Tensor aligned = o_.concat_source || o_.preconditioning == "source"
                                    ? AlignedSource(target_padding, c)
                                    : torch::Tensor();
  const torch::Tensor concatenated = o_.concat_source ? aligned : torch::Tensor();
  Prediction p = o_.variant == "mdt" ? ForwardMdt(xt, t, target_padding, c, concatenated)
                                     : ForwardEncoder(xt, t, target_padding, c, concatenated);
  if (o_.preconditioning == "edm") {
    const auto [skip, out] = schedule_.Preconditioning(t, o_.sigma_data);
    p.x0 = skip * xt + out * p.x0;
    return p;
  }
  torch::Tensor base;  // the estimate's prior mean: the aligned source, or 0
  if (o_.preconditioning == "source") {
    base = aligned;
    p.x0 = base + p.x0;
  }
  if (skip_.defined()) {
    // x0 += s(t) (x_t - sqrt(abar_t) base), a gain per step and feature column on what x_t says
    // beyond the prior mean: a diagonal Wiener filter. It starts at the optimum for Gaussian data
    // of spread sigma_data about the prior mean, s = sqrt(abar) sd^2 / (abar sd^2 + 1 - abar)
    // (about 1 near t = 0, so the clean target passes by the width-d trunk, 0 at t = T), plus a
    // learned correction from 0, so the loss sets how much of x_t to trust where the trunk
    // cannot remove x_t's noise.
    const auto abar = torch::tensor(schedule_.alpha_bar(), torch::kFloat64)
                          .index_select(0, t.to(torch::kInt64));  // [N]
    const double sd2 = o_.sigma_data * o_.sigma_data;
    const auto wiener = (abar.sqrt() * sd2 / (abar * sd2 + 1 - abar)).to(xt.dtype());
    const auto root = abar.sqrt().to(xt.dtype()).view({1, -1, 1});
    const auto gain = (skip_.index_select(0, t.to(torch::kInt64)) + wiener.view({-1, 1}))
                          .unsqueeze(0);  // [1, N, diffusion_dim()]
    p.x0 = p.x0 + gain * (base.defined() ? xt - root * base : xt);
  }
  return p;
}

int64_t EditorNetImpl::diffusion_dim() const {
  return o_.components > 0 ? o_.components : kEditFeatureDim;
}

torch::Tensor EditorNetImpl::Encode(const torch::Tensor& x) const {
  if (!basis_.defined()) return x;
  return torch::matmul(x, basis_) / basis_scale_;
}

torch::Tensor EditorNetImpl::Decode(const torch::Tensor& z) const {
  if (!basis_.defined()) return z;
  return torch::matmul(z * basis_scale_, basis_.t());
}

double EditorNetImpl::FitFrameBasis(const torch::Tensor& covariance) {
  if (!basis_.defined()) throw std::logic_error("FitFrameBasis: diffusion.components is 0");
  double explained = 0;
  auto [basis, scale] = PrincipalFrameBasis(covariance, o_.components, o_.sigma_data, &explained);
  if (!o_.whiten) scale = torch::ones_like(scale);  // an orthonormal projection only
  torch::NoGradGuard no_grad;
  basis_.copy_(basis);
  basis_scale_.copy_(scale);
  return explained;
}

std::pair<torch::Tensor, torch::Tensor> PrincipalFrameBasis(const torch::Tensor& covariance,
                                                            int64_t components, double sigma_data,
                                                            double* explained) {
  const int64_t c = covariance.size(0);
  if (covariance.dim() != 2 || covariance.size(1) != c || components < 1 || components > c)
    throw std::invalid_argument("PrincipalFrameBasis: a square covariance and 1 <= k <= C");
  // Symmetric eigendecomposition in double; eigenvalues ascending.
  const auto [values, vectors] = torch::linalg_eigh(covariance.to(torch::kFloat64));
  const auto top = torch::arange(c - 1, c - 1 - components, -1, torch::kInt64);
  auto basis = vectors.index_select(1, top);                     // [C, k]
  const auto lambda = values.index_select(0, top).clamp_min(0);  // [k]
  // Fix each axis's sign: its entry of largest magnitude is positive.
  const auto peak = basis.abs().argmax(0);                                 // [k]
  const auto sign = basis.gather(0, peak.unsqueeze(0)).sign().squeeze(0);  // [k]
  basis = basis * torch::where(sign == 0, torch::ones_like(sign), sign);
  // A direction with no spread keeps scale 1: dividing by 0 would blow its (zero) coordinate up.
  const auto spread = lambda.sqrt() / sigma_data;
  const auto scale = torch::where(spread > 1e-6, spread, torch::ones_like(spread));
  if (explained) {
    const double total = values.clamp_min(0).sum().item<double>();
    *explained = total > 0 ? lambda.sum().item<double>() / total : 1.0;
  }
  return {basis.to(torch::kFloat32).contiguous(), scale.to(torch::kFloat32).contiguous()};
}

torch::Tensor AlignSource(const torch::Tensor& source, const torch::Tensor& source_padding,
                          const torch::Tensor& target_padding) {
  const int64_t tt = target_padding.size(1), n = source.size(1);
  const auto ls = source_padding.logical_not().sum(1).clamp_min(1).view({1, -1});  // [1, N]
  const auto lt = target_padding.logical_not().sum(1).clamp_min(1).view({1, -1});
  const auto i = torch::arange(tt, torch::kInt64).view({-1, 1});               // [Tt, 1]
  const auto index = torch::minimum(torch::div(i * ls, lt, "floor"), ls - 1);  // [Tt, N]
  return source.gather(0, index.unsqueeze(2).expand({tt, n, source.size(2)}));
}

namespace {

// The source's padding with whole sources removed where they are dropped.
torch::Tensor SourcePadding(const Condition& c) {
  if (!c.drop_source.defined()) return c.source_padding;
  return c.source_padding.logical_or(c.drop_source.view({-1, 1}));
}

}  // namespace

torch::Tensor EditorNetImpl::AlignedSource(const torch::Tensor& target_padding,
                                           const Condition& c) const {
  auto aligned = Encode(AlignSource(c.source, c.source_padding, target_padding));
  if (c.drop_source.defined())
    aligned = aligned * (1 - c.drop_source.view({1, -1, 1}).to(aligned.dtype()));
  return aligned;
}

torch::Tensor EditorNetImpl::TargetTokens(const torch::Tensor& xt, const torch::Tensor& aligned) {
  if (!aligned.defined()) return nn::ApplyLinear(target_in_, xt);
  return nn::ApplyLinear(target_in_, torch::cat({xt, aligned.to(xt.dtype())}, 2));
}

Prediction EditorNetImpl::ForwardMdt(const torch::Tensor& xt, const torch::Tensor& t,
                                     const torch::Tensor& target_padding, const Condition& c,
                                     const torch::Tensor& aligned) {
  const int64_t n = xt.size(1), ts = c.source.size(0), tt = xt.size(0);
  auto [text, tokens] = EncodeText(c);
  const auto source_padding = SourcePadding(c);
  auto source = nn::ApplyLinear(source_in_, c.source);  // [Ts, N, d]
  if (c.drop_source.defined())
    source = source * (1 - c.drop_source.view({1, -1, 1}).to(source.dtype()));
  // Condition transformer over [text token; source frames] at positions 0..Ts, with
  // model.text_tokens the tokens between them (their own positions and the text segment's
  // embedding; the source keeps its positions, whatever the texts' lengths).
  const auto positions = nn::PositionalEncoding(ts + 1, o_.dim);
  std::vector<torch::Tensor> parts = {text.unsqueeze(0) + positions.narrow(0, 0, 1)};
  std::vector<torch::Tensor> masks = {AnyPadding(n, 1)};
  const int64_t words = o_.text_tokens ? tokens.tokens.size(0) : 0;
  // A dropped text's tokens are masked wherever they are read, not only zeroed: how many there
  // were is a trace of it.
  const auto word_mask =
      c.drop_text.defined() ? tokens.padding.logical_or(c.drop_text.view({-1, 1})) : tokens.padding;
  if (o_.text_tokens) {
    parts.push_back(tokens.tokens + nn::PositionalEncoding(words, o_.dim) +
                    segments_[kText].view({1, 1, -1}));
    masks.push_back(word_mask);
  }
  parts.push_back(source + positions.narrow(0, 1, ts));
  masks.push_back(source_padding);
  const auto h = condition_->forward(torch::cat(parts, 0), torch::cat(masks, 1));
  const auto enhanced_text = h[0];
  const auto enhanced_source = h.narrow(0, 1 + words, ts);
  Prediction p;
  if (o_.aux != "none") {
    auto s = nn::ApplySequential(sim_head_, enhanced_source).transpose(0, 1);  // [N, Ts, K]
    p.similarity = o_.aux == "regression" ? s.squeeze(2) : s;
  }
  // DiT over [source; separator; noisy target] (with model.time_token the timestep and with
  // model.dit_text_tokens the text's tokens first), conditioned on timestep (+ text); or, with
  // model.trunk encoder, TMED's encoder layers over [timestep; text tokens; source; separator;
  // noisy target].
  const bool encoder_trunk = o_.trunk == "encoder";
  const bool time_token = o_.time_token || encoder_trunk;
  const bool text_in_trunk = o_.dit_text_tokens || encoder_trunk;
  const auto cond_time = TimeEmbedding(t);
  const auto src = o_.enhanced_motion ? enhanced_source : source;
  std::vector<torch::Tensor> sequence, paddings;
  if (time_token) {
    sequence.push_back(Place(cond_time.unsqueeze(0), kTime));
    paddings.push_back(AnyPadding(n, 1));
  }
  if (text_in_trunk) {
    sequence.push_back(Place(o_.text_tokens ? h.narrow(0, 1, words) : tokens.tokens, kText));
    paddings.push_back(word_mask);
  }
  int64_t prefix = ts + 1;  // the target's offset: every token before it
  for (const auto& part : sequence) prefix += part.size(0);
  sequence.insert(
      sequence.end(),
      {Place(src, kSource), Place(separator_.view({1, 1, -1}).expand({1, n, o_.dim}), kSeparator),
       Place(TargetTokens(xt, aligned), kTarget)});
  paddings.insert(paddings.end(), {source_padding, AnyPadding(n, 1), target_padding});
  auto x = torch::cat(sequence, 0);
  const auto padding = torch::cat(paddings, 1);
  if (encoder_trunk) {
    x = encoder_->forward(x, padding).narrow(0, prefix, tt);
  } else {
    auto cond = cond_time;
    if (o_.adaln_text) cond = cond + TextCondition(o_.enhanced_text ? enhanced_text : text);
    const auto silu_cond = torch::silu(cond);  // every block's adaLN input, computed once
    for (const auto& block : *blocks_) x = block->as<DiTBlock>()->forward(x, silu_cond, padding);
    const auto m = nn::ApplyLinear(final_modulation_, silu_cond).unsqueeze(0).chunk(2, 2);
    x = Modulate(x.narrow(0, prefix, tt), m[1], m[0]);
  }
  p.x0 = nn::ApplyLinear(out_, x);
  if (contact_out_) p.contacts = nn::ApplyLinear(contact_out_, x);
  return p;
}

Prediction EditorNetImpl::ForwardEncoder(const torch::Tensor& xt, const torch::Tensor& t,
                                         const torch::Tensor& target_padding, const Condition& c,
                                         const torch::Tensor& aligned) {
  const int64_t n = xt.size(1), tt = xt.size(0);
  auto [text, tokens] = EncodeText(c);
  const auto time = TimeEmbedding(t).unsqueeze(0);  // [1, N, d]
  std::vector<torch::Tensor> parts, masks;
  if (o_.variant == "mdm") {
    parts = {Place(time + text.unsqueeze(0), kTime)};  // MDM: one condition token
    masks = {AnyPadding(n, 1)};
  } else {  // TMED: [timestep; text tokens; source; separator; noisy target]
    auto source = nn::ApplyLinear(source_in_, c.source);
    if (c.drop_source.defined())
      source = source * (1 - c.drop_source.view({1, -1, 1}).to(source.dtype()));
    parts = {Place(time, kTime), Place(tokens.tokens, kText), Place(source, kSource),
             Place(separator_.view({1, 1, -1}).expand({1, n, o_.dim}), kSeparator)};
    masks = {AnyPadding(n, 1), tokens.padding, SourcePadding(c), AnyPadding(n, 1)};
  }
  int64_t prefix = 0;
  for (const auto& part : parts) prefix += part.size(0);
  parts.push_back(Place(TargetTokens(xt, aligned), kTarget));
  masks.push_back(target_padding);
  auto x = torch::cat(parts, 0);
  x = encoder_->forward(x, torch::cat(masks, 1)).narrow(0, prefix, tt);
  Prediction p{nn::ApplyLinear(out_, x), {}, {}};
  if (contact_out_) p.contacts = nn::ApplyLinear(contact_out_, x);
  return p;
}

torch::Tensor GroupedMaskedMse(const torch::Tensor& prediction, const torch::Tensor& target,
                               const torch::Tensor& padding, const torch::Tensor& weight,
                               const torch::Tensor& columns) {
  const auto keep = padding.logical_not().t().unsqueeze(2).to(prediction.dtype());  // [T, N, 1]
  const auto frames = keep.sum(0).squeeze(1).clamp_min(1.0);                        // [N]
  auto squared = (prediction - target).pow(2) * keep;
  if (columns.defined()) squared = squared * columns.to(squared.dtype());
  std::vector<torch::Tensor> groups;
  for (const auto& g : MotionFixFeatureGroups()) {
    const std::vector<int64_t> dims = {0, 2};
    groups.push_back(squared.narrow(2, g.begin, g.end - g.begin).sum(dims) /
                     (frames * (g.end - g.begin)));  // [N]
  }
  const auto per_example = torch::stack(groups, 0).mean(0);
  return weight.defined() ? (per_example * weight).mean() : per_example.mean();
}

torch::Tensor VelocityMse(const torch::Tensor& prediction, const torch::Tensor& target,
                          const torch::Tensor& padding) {
  const int64_t frames = prediction.size(0);
  if (frames < 2) return torch::zeros({}, prediction.options());
  const auto difference = [&](const torch::Tensor& x) {
    return x.narrow(0, 1, frames - 1) - x.narrow(0, 0, frames - 1);
  };
  const auto both = padding.narrow(1, 1, frames - 1).logical_or(padding.narrow(1, 0, frames - 1));
  return GroupedMaskedMse(difference(prediction), difference(target), both);
}

std::map<std::string, torch::Tensor> SimilarityLoss(
    const torch::Tensor& prediction, const torch::Tensor& classes, const torch::Tensor& similarity,
    const torch::Tensor& source_padding, const torch::Tensor& drop_source, const EditorOptions& o) {
  auto valid = classes.ge(0).logical_and(source_padding.logical_not());
  if (drop_source.defined()) valid = valid.logical_and(drop_source.view({-1, 1}).logical_not());
  const auto w = valid.to(torch::kFloat32);
  std::map<std::string, torch::Tensor> out;
  if (o.aux == "classes") {
    const auto labels = classes.clamp_min(0);
    const auto nll =
        -torch::log_softmax(prediction, 2).gather(2, labels.unsqueeze(2)).squeeze(2);  // [N, Ts]
    const auto weights = torch::tensor(o.class_weights, torch::kFloat64)
                             .to(torch::kFloat32)
                             .index_select(0, labels.view({-1}))
                             .view_as(nll) *
                         w;
    out["aux"] = (nll * weights).sum() / weights.sum().clamp_min(1e-8);
    out["aux_accuracy"] =
        (prediction.argmax(2).eq(labels).to(torch::kFloat32) * w).sum() / w.sum().clamp_min(1.0);
  } else {
    out["aux"] =
        ((torch::sigmoid(prediction) - similarity).pow(2) * w).sum() / w.sum().clamp_min(1.0);
  }
  return out;
}

torch::Tensor LegColumnWeights(double leg_weight) {
  const auto parts = PartColumns();
  const auto legs = parts[static_cast<int64_t>(BodyPart::kLeftLeg)].logical_or(
      parts[static_cast<int64_t>(BodyPart::kRightLeg)]);
  return torch::where(legs, torch::full({kEditFeatureDim}, leg_weight),
                      torch::ones({kEditFeatureDim}));
}

torch::Tensor PartColumns() {
  auto columns = torch::zeros({kNumBodyParts, kEditFeatureDim}, torch::kBool);
  const Skeleton& skeleton = Skeleton::Smpl22();
  const auto global = static_cast<int64_t>(BodyPart::kGlobal);
  columns[global].narrow(0, 0, 15).fill_(true);  // pelvis velocity, orientation, heading change
  for (int j = 0; j < kNumJoints; ++j) {
    const auto part = static_cast<int64_t>(skeleton.part_of_joint(j));
    if (j > 0) columns[part].narrow(0, 15 + 6 * (j - 1), 6).fill_(true);
    columns[part].narrow(0, 141 + 3 * j, 3).fill_(true);
  }
  return columns;
}

}  // namespace motionpipe::mdt
