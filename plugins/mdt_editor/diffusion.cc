#include "diffusion.h"

#include <algorithm>
#include <cmath>

namespace motionpipe::mdt {

CosineSchedule::CosineSchedule(int64_t steps, double snr_shift) : steps_(steps) {
  if (steps < 2) throw std::invalid_argument("diffusion.steps must be at least 2");
  if (!(snr_shift >= 1) || snr_shift > 1e3)
    throw std::invalid_argument("diffusion.snr_shift must be in [1, 1000]");
  constexpr double s = 0.008, half_pi = 1.57079632679489661923;
  const auto f = [&](double t) {
    const double c = std::cos((t / static_cast<double>(steps) + s) / (1 + s) * half_pi);
    return c * c;
  };
  double product = 1;
  for (int64_t t = 0; t < steps; ++t) {
    const double beta =
        std::min(1 - f(static_cast<double>(t + 1)) / f(static_cast<double>(t)), 0.999);
    product *= 1 - beta;
    alpha_bar_.push_back(product);
  }
  if (snr_shift != 1) {
    const double shift = 2 * std::log(snr_shift);
    for (double& abar : alpha_bar_)
      abar = 1 / (1 + std::exp(-(std::log(abar / (1 - abar)) - shift)));
  }
  double previous = 1;
  for (int64_t t = 0; t < steps; ++t) {
    const double abar = alpha_bar_[static_cast<size_t>(t)];
    const double beta = 1 - abar / previous;
    betas_.push_back(beta);
    // q(x_{t-1} | x_t, x0): variance beta (1 - abar_{t-1}) / (1 - abar_t), mean coefficients.
    posterior_variance_.push_back(beta * (1 - previous) / (1 - abar));
    coef_x0_.push_back(beta * std::sqrt(previous) / (1 - abar));
    coef_xt_.push_back((1 - previous) * std::sqrt(1 - beta) / (1 - abar));
    previous = abar;
  }
}

torch::Tensor CosineSchedule::QSample(const torch::Tensor& x0, const torch::Tensor& t,
                                      const torch::Tensor& noise) const {
  const auto abar = torch::tensor(alpha_bar_, torch::kFloat64)
                        .to(torch::kFloat32)
                        .index_select(0, t.to(torch::kInt64));  // [N]
  const auto a = abar.sqrt().view({1, -1, 1});
  const auto b = (1 - abar).sqrt().view({1, -1, 1});
  return a * x0 + b * noise;
}

std::pair<torch::Tensor, torch::Tensor> CosineSchedule::Preconditioning(const torch::Tensor& t,
                                                                        double sigma_data) const {
  const auto abar =
      torch::tensor(alpha_bar_, torch::kFloat64).index_select(0, t.to(torch::kInt64));  // [N]
  const double sd2 = sigma_data * sigma_data;
  const auto denominator = 1 - abar + sd2 * abar;
  const auto skip = sd2 * abar.sqrt() / denominator;
  const auto out = sigma_data * (1 - abar).sqrt() / denominator.sqrt();
  return {skip.to(torch::kFloat32).view({1, -1, 1}), out.to(torch::kFloat32).view({1, -1, 1})};
}

torch::Tensor CosineSchedule::PosteriorMean(const torch::Tensor& x0, const torch::Tensor& xt,
                                            int64_t t) const {
  return coef_x0_[static_cast<size_t>(t)] * x0 + coef_xt_[static_cast<size_t>(t)] * xt;
}

torch::Tensor CosineSchedule::DdimStep(const torch::Tensor& x0, const torch::Tensor& xt, int64_t t,
                                       int64_t t_prev) const {
  if (t_prev < 0) return x0;
  const double abar = alpha_bar_[static_cast<size_t>(t)],
               abar_prev = alpha_bar_[static_cast<size_t>(t_prev)];
  const auto eps = (xt - std::sqrt(abar) * x0) / std::sqrt(1 - abar);
  return std::sqrt(abar_prev) * x0 + std::sqrt(1 - abar_prev) * eps;
}

torch::Tensor SampleDdpm(const CosineSchedule& schedule, at::IntArrayRef shape,
                         const Denoise& denoise, torch::Generator generator,
                         const Projection& project) {
  torch::NoGradGuard no_grad;
  auto x = torch::randn(shape, generator);
  for (int64_t t = schedule.steps() - 1; t >= 0; --t) {
    auto x0 = denoise(x, t);
    if (project) x0 = project(x0, t);
    if (t == 0) return x0;
    x = schedule.PosteriorMean(x0, x, t) +
        std::sqrt(schedule.PosteriorVariance(t)) * torch::randn(shape, generator);
  }
  return x;
}

std::vector<int64_t> DdimTimesteps(int64_t total, int64_t steps) {
  steps = std::clamp<int64_t>(steps, 1, total);
  std::vector<int64_t> out;
  for (int64_t k = steps - 1; k >= 0; --k) {
    // Evenly spaced from T - 1 down to 0.
    out.push_back(
        static_cast<int64_t>(std::llround(static_cast<double>(k) * static_cast<double>(total - 1) /
                                          std::max<double>(1, static_cast<double>(steps - 1)))));
  }
  if (steps == 1) out = {total - 1};
  return out;
}

torch::Tensor SampleDdim(const CosineSchedule& schedule, at::IntArrayRef shape, int64_t steps,
                         const Denoise& denoise, torch::Generator generator,
                         const Projection& project) {
  torch::NoGradGuard no_grad;
  auto x = torch::randn(shape, generator);
  const auto ts = DdimTimesteps(schedule.steps(), steps);
  for (size_t k = 0; k < ts.size(); ++k) {
    auto x0 = denoise(x, ts[k]);
    if (project) x0 = project(x0, ts[k]);
    x = schedule.DdimStep(x0, x, ts[k], k + 1 < ts.size() ? ts[k + 1] : -1);
  }
  return x;
}

torch::Tensor SampleDdimFromNoised(const CosineSchedule& schedule, const torch::Tensor& start,
                                   int64_t t_start, int64_t steps, const Denoise& denoise,
                                   torch::Generator generator, const Projection& project) {
  torch::NoGradGuard no_grad;
  if (t_start < 0 || t_start >= schedule.steps())
    throw std::invalid_argument("SampleDdimFromNoised: t_start outside the schedule");
  const auto noise = torch::randn(start.sizes(), generator);
  auto x = schedule.QSample(start, torch::full({start.size(1)}, t_start, torch::kInt64), noise);
  const auto ts = DdimTimesteps(t_start + 1, std::min(steps, t_start + 1));
  for (size_t k = 0; k < ts.size(); ++k) {
    auto x0 = denoise(x, ts[k]);
    if (project) x0 = project(x0, ts[k]);
    x = schedule.DdimStep(x0, x, ts[k], k + 1 < ts.size() ? ts[k + 1] : -1);
  }
  return x;
}

torch::Tensor GuideThreeWay(const torch::Tensor& u, const torch::Tensor& c_m,
                            const torch::Tensor& c_tm, double g_m, double g_t) {
  return u + g_m * (c_m - u) + g_t * (c_tm - c_m);
}

torch::Tensor TimestepEmbedding(const torch::Tensor& t, int64_t dim) {
  const int64_t half = dim / 2;
  const auto freqs = torch::exp(-std::log(10000.0) * torch::arange(half, torch::kFloat32) /
                                static_cast<double>(half));
  const auto args = t.to(torch::kFloat32).unsqueeze(1) * freqs.unsqueeze(0);
  auto emb = torch::cat({torch::cos(args), torch::sin(args)}, 1);
  if (dim % 2) emb = torch::cat({emb, torch::zeros({t.size(0), 1})}, 1);
  return emb;
}

int64_t SampleTrainingStep(int64_t steps, double power, torch::Generator generator) {
  if (power == 0) return torch::randint(steps, {1}, generator).item<int64_t>();
  const double u = torch::rand({1}, generator, torch::kFloat64).item<double>();
  const auto t =
      static_cast<int64_t>(std::floor(static_cast<double>(steps) * std::pow(u, 1 / (power + 1))));
  return std::clamp<int64_t>(t, 0, steps - 1);
}

torch::Tensor MinSnrWeights(const CosineSchedule& schedule, const torch::Tensor& t, double gamma) {
  const auto abar = torch::tensor(schedule.alpha_bar(), torch::kFloat64);
  const auto clamped = (abar / (1 - abar)).clamp_max(gamma);  // [steps]
  return (clamped.index_select(0, t.to(torch::kInt64)) / clamped.mean()).to(torch::kFloat32);
}

}  // namespace motionpipe::mdt
