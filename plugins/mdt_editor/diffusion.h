// Gaussian diffusion for the editing models (REFERENCE 3.2): the cosine schedule of Nichol &
// Dhariwal with T = 300, x0 prediction, DDPM ancestral sampling with the fixed-small posterior
// variance, DDIM (eta = 0) on a strided subset of the steps, and classifier-free guidance.
#pragma once

#include <torch/torch.h>

#include <functional>
#include <vector>

namespace motionpipe::mdt {

class CosineSchedule {
 public:
  // alpha_bar(t) = f(t) / f(0), f(t) = cos^2(((t / T) + s) / (1 + s) * pi / 2), s = 0.008;
  // beta_t = min(1 - alpha_bar(t + 1) / alpha_bar(t), 0.999).
  // snr_shift k > 1 shifts the schedule towards noise, as Hoogeboom et al. 2023 ("simple
  // diffusion") do for redundant high-resolution data: logSNR'(t) = logSNR(t) - 2 log k, i.e.
  // alpha_bar'(t) = sigmoid(logit(alpha_bar(t)) - 2 log k); betas follow from the ratios. k = 1 is
  // the reference schedule.
  explicit CosineSchedule(int64_t steps = 300, double snr_shift = 1);
  int64_t steps() const { return steps_; }
  const std::vector<double>& betas() const { return betas_; }
  const std::vector<double>& alpha_bar() const {
    return alpha_bar_;
  }  // after step t: prod_{k<=t} (1 - beta_k)
  // x_t = sqrt(alpha_bar_t) x0 + sqrt(1 - alpha_bar_t) eps, t per example [N] (sequence-first x [T,
  // N, D]).
  torch::Tensor QSample(const torch::Tensor& x0, const torch::Tensor& t,
                        const torch::Tensor& noise) const;
  // The posterior q(x_{t-1} | x_t, x0): mean and the fixed-small variance beta~_t.
  torch::Tensor PosteriorMean(const torch::Tensor& x0, const torch::Tensor& xt, int64_t t) const;
  double PosteriorVariance(int64_t t) const { return posterior_variance_[static_cast<size_t>(t)]; }
  // The DDIM (eta = 0) update from step t to step t_prev (< t; -1 = the end) given the x0
  // prediction.
  torch::Tensor DdimStep(const torch::Tensor& x0, const torch::Tensor& xt, int64_t t,
                         int64_t t_prev) const;
  // Karras et al. 2022 (EDM), eq. 7 and table 1, for this variance-preserving schedule: with
  // x~ = x_t / sqrt(abar) = x0 + sigma eps, sigma^2 = (1 - abar) / abar, the x0 estimate is
  // D = c_skip x~ + c_out F, c_skip = sd^2 / (sigma^2 + sd^2), c_out = sigma sd / sqrt(sigma^2 +
  // sd^2). Returns {c_skip / sqrt(abar), c_out} per example as [1, N, 1], the first to multiply x_t
  // itself: sd^2 sqrt(abar) / (1 - abar + sd^2 abar) and sd sqrt(1 - abar) / sqrt(1 - abar + sd^2
  // abar), finite at every step (abar -> 0 at t = T - 1).
  std::pair<torch::Tensor, torch::Tensor> Preconditioning(const torch::Tensor& t,
                                                          double sigma_data) const;

 private:
  int64_t steps_;
  std::vector<double> betas_, alpha_bar_, posterior_variance_, coef_x0_, coef_xt_;
};

// A training example's diffusion step. power 0: uniform over [0, steps) (the reference; the same
// draw as torch::randint). power k > 0: density proportional to (t + 1/2)^k, drawn as
// floor(steps u^(1 / (k + 1))) from one uniform u, so that more of the training lands on the noisy
// steps, where the source prior's edit is decided by the text (issue 15: text and source move the
// estimate only at t >= 250 of 300); not in the paper, a loss weighting over steps as EDM's and
// SD3's step densities are.
int64_t SampleTrainingStep(int64_t steps, double power, torch::Generator generator);

// Min-SNR-gamma loss weights (Hang et al. 2023, "Efficient Diffusion Training via Min-SNR Weighting
// Strategy", for x0 prediction: w_t = min(SNR_t, gamma), SNR_t = abar_t / (1 - abar_t)) of the
// steps t [N], divided by their mean over the schedule's steps so that under uniform steps the loss
// keeps its scale: every step with SNR above gamma (the low-noise end, where the fine detail such
// as the feet's contacts is made) weighs the same, the noisiest steps almost nothing. Not in the
// paper (issue 15: the MDT's estimate from a clean target still skates; measured, it does not
// help). Returns float32 [N].
torch::Tensor MinSnrWeights(const CosineSchedule& schedule, const torch::Tensor& t, double gamma);

// The model's x0 prediction at step t for the current x_t (guidance already applied).
using Denoise = std::function<torch::Tensor(const torch::Tensor& xt, int64_t t)>;
// An edit of the x0 prediction at step t before the sampler steps from it (MDM-BP's body-part
// inpainting, foot locking); empty: none.
using Projection = std::function<torch::Tensor(const torch::Tensor& x0, int64_t t)>;

// DDPM ancestral sampling over every step: x_T ~ N(0, I), x_{t-1} = mean + sqrt(beta~_t) z (no
// noise at the last step). `project` (optional) edits each x0 prediction.
torch::Tensor SampleDdpm(const CosineSchedule& schedule, at::IntArrayRef shape,
                         const Denoise& denoise, torch::Generator generator,
                         const Projection& project = {});
// DDIM with `steps` evenly spaced steps (the last one is T - 1).
torch::Tensor SampleDdim(const CosineSchedule& schedule, at::IntArrayRef shape, int64_t steps,
                         const Denoise& denoise, torch::Generator generator,
                         const Projection& project = {});
// SDEdit (Meng et al. 2022), not in SimMotionEdit: `start` noised to step t_start (x_t =
// sqrt(abar) start + sqrt(1 - abar) eps) and DDIM from there to the end in `steps` evenly spaced
// steps. The sample keeps what the noise at t_start leaves of `start`; t_start = T - 1 is close
// to SampleDdim.
torch::Tensor SampleDdimFromNoised(const CosineSchedule& schedule, const torch::Tensor& start,
                                   int64_t t_start, int64_t steps, const Denoise& denoise,
                                   torch::Generator generator, const Projection& project = {});
// The DDIM step indices, descending, for `steps` of a `total`-step schedule.
std::vector<int64_t> DdimTimesteps(int64_t total, int64_t steps);

// Three-way classifier-free guidance (SimMotionEdit): u + g_m (c_m - u) + g_t (c_tm - c_m), where
// u has no condition, c_m the source motion only and c_tm the text and the source.
torch::Tensor GuideThreeWay(const torch::Tensor& u, const torch::Tensor& c_m,
                            const torch::Tensor& c_tm, double g_m, double g_t);

// Sinusoidal embedding of diffusion steps [N] -> [N, dim] (cos half, then sin half, as DiT).
torch::Tensor TimestepEmbedding(const torch::Tensor& t, int64_t dim);

}  // namespace motionpipe::mdt
