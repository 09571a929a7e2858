// SimMotionEdit's MDT (plugins/mdt_editor): training samples/s at the demo's size and at the
// paper's against the same architecture in PyTorch Python (bench/reference/mdt_ref.py, Debian's
// python3-torch) on the same batch with the same threads, in one run; then editing latency per
// motion with three-way guidance for DDPM-300 and DDIM-50 at batch 1 and 32. The training rate is
// also given in GFLOP/s (the step's matrix products counted, TrainingStepFlops) beside the sgemm
// rate of LibTorch on the same threads, measured in the same run (issue 15: goal 60% of it at
// paper size), and the same step under bf16 autocast (plugins/common/precision.h) as the ratio
// bf16/f32 of samples/s. The step clips and steps AdamW with the fused kernel, as the train stage
// does; the fused kernels (plugins/common/fused.h: tanh-GELU, adaLN's modulated LayerNorm and
// gated residual, clip + AdamW, attention's float32 core) and ATen's linear (nn::ApplyLinear, for a
// DiT block's four linears) are then timed against the LibTorch route they replace on the same
// inputs at the training shape, forward and backward, with the share each saves of the step of its
// precision (float32; bf16 where this CPU has bf16 products).
// With --profile N, N steps of the first size, in the precision the train stage runs for bf16 on
// this CPU (float32 where its bf16 products are emulated), run under LibTorch's profiler and the
// operators are listed by their own (self) time per step, to show where a step goes besides the
// matrix products.
//   mdt_bench [--sizes demo,paper] [--steps K] [--threads T] [--batch N] [--frames F]
//             [--no-reference] [--no-latency] [--no-fused] [--profile N]
#include <torch/csrc/autograd/profiler_legacy.h>
#include <torch/torch.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "../plugins/common/fused.h"
#include "../plugins/common/precision.h"
#include "../plugins/common/threads.h"
#include "../plugins/mdt_editor/editor.h"
#include "bench_util.h"
#include "flops.h"
#include "motionpipe/formats/npy.h"

namespace fs = std::filesystem;
using namespace motionpipe;
using namespace motionpipe::mdt;
using bench::Clock;
using bench::ExamplesPerSecond;
using bench::LayerMacs;
using bench::Run;
using bench::SgemmGflops;
using bench::Since;
using nlohmann::json;

namespace {

struct Size {
  std::string name;
  int64_t dim, cond_layers, layers, heads, ff;
};

std::vector<std::string> Texts(int64_t n) {
  const char* edits[] = {"raise the right arm higher",
                         "walk faster",
                         "bend the knees more",
                         "do not turn at the end",
                         "kick with the left leg instead",
                         "lower the arms",
                         "take bigger steps",
                         "jump higher"};
  std::vector<std::string> t;
  for (int64_t i = 0; i < n; ++i)
    t.push_back(edits[i % 8] + std::string(i % 3 == 0 ? " please" : ""));
  return t;
}

template <typename T>
std::vector<T> Values(const torch::Tensor& t) {
  const auto c = t.contiguous();
  return std::vector<T>(c.data_ptr<T>(), c.data_ptr<T>() + c.numel());
}

// FLOPs of one training step of the MDT, counted from its matrix products (everything else is a
// few percent at these sizes): forward 2 x multiply-adds, backward twice the forward (gradients of
// inputs and of weights). The text encoder is the text_encoder options' size.
double TrainingStepFlops(const Size& size, double batch, double frames, double text_tokens,
                         const nn::TextEncoderOptions& text) {
  const double d = static_cast<double>(size.dim), ff = static_cast<double>(size.ff);
  double macs = 0;
  macs +=
      LayerMacs(batch, text_tokens, static_cast<double>(text.dim), static_cast<double>(text.ff)) *
      static_cast<double>(text.layers);
  macs += batch * text_tokens * static_cast<double>(text.dim) * d;  // text projection
  macs += batch * frames * kEditFeatureDim * d * 3;                 // source in, target in, out
  macs += LayerMacs(batch, frames + 1, d, ff) * static_cast<double>(size.cond_layers);
  macs += LayerMacs(batch, 2 * frames + 1, d, ff) * static_cast<double>(size.layers);
  macs += batch * frames * (d * ff + ff * ff + ff * 3);  // the similarity head
  return 3 * 2 * macs;
}

EditorNet Build(const Size& size) {
  const json config = {
      {"variant", "mdt"},
      {"model",
       {{"dim", size.dim},
        {"cond_layers", size.cond_layers},
        {"layers", size.layers},
        {"heads", size.heads},
        {"ff", size.ff},
        {"sim_hidden", size.ff},
        {"dropout", 0.1},
        {"text_encoder",
         {{"layers", 1}, {"vocab", 1000}, {"heads", size.heads}, {"ff", size.ff}}}}}};
  EditorNet net(EditorOptions::FromJson(config));
  net->text_encoder()->Fit(Texts(64));
  return net;
}

struct Args {
  std::string sizes = "demo,paper";
  int64_t steps = 4, threads = 1, batch = 32, frames = 150;
  int64_t profile = 0;  // bf16 steps run under the profiler (0: none)
  bool reference = true, latency = true, fused = true;
};

std::optional<Args> ParseArgs(int argc, char** argv) {
  Args a;
  for (int k = 1; k < argc; ++k) {
    if (!std::strcmp(argv[k], "--sizes") && k + 1 < argc)
      a.sizes = argv[++k];
    else if (!std::strcmp(argv[k], "--steps") && k + 1 < argc)
      a.steps = std::atoll(argv[++k]);
    else if (!std::strcmp(argv[k], "--threads") && k + 1 < argc)
      a.threads = std::atoll(argv[++k]);
    else if (!std::strcmp(argv[k], "--batch") && k + 1 < argc)
      a.batch = std::atoll(argv[++k]);
    else if (!std::strcmp(argv[k], "--frames") && k + 1 < argc)
      a.frames = std::atoll(argv[++k]);
    else if (!std::strcmp(argv[k], "--no-reference"))
      a.reference = false;
    else if (!std::strcmp(argv[k], "--no-latency"))
      a.latency = false;
    else if (!std::strcmp(argv[k], "--no-fused"))
      a.fused = false;
    else if (!std::strcmp(argv[k], "--profile") && k + 1 < argc)
      a.profile = std::atoll(argv[++k]);
    else
      return std::nullopt;
  }
  return a;
}

// The training batch: lengths in [frames/2, frames], features ~ N(0, 1), classes in {0, 1, 2}.
struct TrainBatch {
  torch::Tensor source_padding, target_padding, source, target, classes;
  std::vector<std::string> texts;
};

TrainBatch MakeTrainBatch(const Args& a) {
  std::mt19937 rng(7);
  const auto lengths = [&](int64_t n) {
    auto padding = torch::zeros({n, a.frames}, torch::kBool);
    for (int64_t i = 0; i < n; ++i) {
      const int64_t length =
          a.frames / 2 + static_cast<int64_t>(rng() % static_cast<uint32_t>(a.frames / 2 + 1));
      padding[i].narrow(0, length, a.frames - length).fill_(true);
    }
    return padding;
  };
  torch::manual_seed(1);
  TrainBatch b;
  b.source_padding = lengths(a.batch);
  b.target_padding = lengths(a.batch);
  b.source = torch::randn({a.frames, a.batch, kEditFeatureDim});
  b.target = torch::randn({a.frames, a.batch, kEditFeatureDim});
  b.classes =
      torch::randint(0, 3, {a.batch, a.frames}, torch::kInt64).masked_fill(b.source_padding, -1);
  b.texts = Texts(a.batch);
  return b;
}

namespace profiler = torch::autograd::profiler;

// Runs `step` `steps` times under LibTorch's (legacy) CPU profiler and prints the operators by
// their self time per step (their time less that of the operators they call, e.g. autograd's
// backward nodes less the kernels inside them), the largest first, down to 1% of the step.
template <typename F>
void Profile(int64_t steps, const char* precision, F&& step) {
  step();  // warm-up outside the profile
  profiler::thread_event_lists lists;
  const auto started = Clock::now();
  {
    profiler::TLSLegacyProfilerGuard guard(
        torch::profiler::impl::ProfilerConfig(torch::profiler::impl::ProfilerState::CPU),
        [&](const profiler::thread_event_lists& recorded) { lists = recorded; });
    for (int64_t k = 0; k < steps; ++k) step();
  }
  const double wall_ms = 1e3 * Since(started) / static_cast<double>(steps);
  struct Row {
    double self_us = 0;
    int64_t calls = 0;
  };
  std::map<std::string, Row> rows;
  double covered_us = 0;  // time inside outermost operators
  for (const auto& list : lists) {
    std::vector<std::pair<const profiler::LegacyEvent*, double>> open;  // push, children's time
    for (const auto& e : list) {
      if (e.kind() == profiler::EventKind::PushRange) {
        open.emplace_back(&e, 0.0);
      } else if (e.kind() == profiler::EventKind::PopRange && !open.empty()) {
        const auto [push, children_us] = open.back();
        open.pop_back();
        const double us = push->cpuElapsedUs(e);
        Row& row = rows[push->name()];
        row.self_us += us - children_us;
        ++row.calls;
        (open.empty() ? covered_us : open.back().second) += us;
      }
    }
  }
  std::vector<std::pair<std::string, Row>> sorted(rows.begin(), rows.end());
  std::sort(sorted.begin(), sorted.end(),
            [](const auto& x, const auto& y) { return x.second.self_us > y.second.self_us; });
  const double n = static_cast<double>(steps);
  std::printf(
      "\nwhere a %s step goes (%lld steps profiled, %.1f ms a step under the profiler, %.1f ms "
      "inside operators): self ms per step\n%-44s %9s %7s %9s\n",
      precision, static_cast<long long>(steps), wall_ms, covered_us / 1e3 / n, "operator", "ms",
      "of step", "calls");
  for (const auto& [name, row] : sorted) {
    const double ms = row.self_us / 1e3 / n;
    if (ms < 0.01 * wall_ms) break;
    std::printf("%-44s %9.2f %6.1f%% %9.0f\n", name.substr(0, 44).c_str(), ms, 100 * ms / wall_ms,
                static_cast<double>(row.calls) / n);
  }
  std::fflush(stdout);
}

// The PyTorch-Python reference (bench/reference/mdt_ref.py) on the same batch: its samples per
// second.
double PythonReference(const Args& a, const Size& size, EditorNet& net, const TrainBatch& b) {
  const std::string dir = "/tmp/motionpipe_mdt_bench";
  fs::create_directories(dir);
  const auto token_ids = net->text_encoder()->TokenIds(b.texts);
  bench::SaveNpy(dir + "/tokens.npy", NpyArray::Int64({token_ids.size(0), token_ids.size(1)},
                                                      Values<int64_t>(token_ids)));
  bench::SaveNpy(dir + "/source.npy",
                 NpyArray::Float32({a.frames, a.batch, kEditFeatureDim}, Values<float>(b.source)));
  bench::SaveNpy(dir + "/target.npy",
                 NpyArray::Float32({a.frames, a.batch, kEditFeatureDim}, Values<float>(b.target)));
  bench::SaveNpy(dir + "/classes.npy",
                 NpyArray::Int64({a.batch, a.frames}, Values<int64_t>(b.classes)));
  for (const auto& [name, pad] : {std::pair{"source_padding", b.source_padding},
                                  std::pair{"target_padding", b.target_padding}}) {
    bench::SaveNpy(dir + "/" + name + ".npy",
                   NpyArray::Bool({a.batch, a.frames}, Values<uint8_t>(pad.to(torch::kUInt8))));
  }
  std::ostringstream command;
  command << "OMP_NUM_THREADS=" << a.threads << " OPENBLAS_NUM_THREADS=" << a.threads
          << " /usr/bin/python3 " << MOTIONPIPE_SOURCE_DIR
          << "/bench/reference/mdt_ref.py --batch-dir " << dir << " --dim " << size.dim
          << " --cond-layers " << size.cond_layers << " --layers " << size.layers << " --heads "
          << size.heads << " --ff " << size.ff << " --steps " << a.steps << " --threads "
          << a.threads;
  const std::string out = Run(command.str());
  return json::parse(out.substr(out.rfind('{'))).at("samples_per_second").get<double>();
}

// Milliseconds of one training step in each precision.
struct StepMs {
  double float32 = 0, bf16 = 0;
};

// One size: our training step's samples/s, the reference's, and our GFLOP/s against the sgemm
// rate measured here; with `profile`, then where a step's time goes. Returns the milliseconds of
// a float32 step and of a step under bf16 autocast (timed as LibTorch runs it on this CPU).
StepMs BenchTraining(const Args& a, const Size& size, const TrainBatch& b, bool profile) {
  torch::manual_seed(1);
  EditorNet net = Build(size);
  const CosineSchedule schedule(300);
  int64_t parameters = 0;
  for (const auto& p : net->parameters()) parameters += p.numel();
  torch::optim::AdamW optimizer(net->parameters(),
                                torch::optim::AdamWOptions(1e-4).weight_decay(0.01));
  net->train();
  const int64_t batch = a.batch;
  const auto step = [&](nn::Precision precision) {
    const auto t = torch::randint(0, 300, {batch}, torch::kInt64);
    const auto u = torch::rand({batch});
    Condition c{b.texts, b.source, b.source_padding, u.lt(0.2),
                u.lt(0.15).logical_or(u.ge(0.2).logical_and(u.lt(0.25)))};
    torch::Tensor loss;
    {
      const nn::MixedPrecision autocast(precision);
      const auto xt = schedule.QSample(b.target, t, torch::randn_like(b.target));
      const Prediction p = net->forward(xt, t, b.target_padding, c);
      loss = GroupedMaskedMse(p.x0, b.target, b.target_padding) +
             0.05 * SimilarityLoss(p.similarity, b.classes, torch::zeros({batch, a.frames}),
                                   b.source_padding, c.drop_source, net->options())
                        .at("aux");
    }
    optimizer.zero_grad();
    loss.backward();
    nn::AdamWStep(optimizer, 1.0);
    return loss.item<double>();
  };
  const auto rate = [&](nn::Precision precision) {
    return ExamplesPerSecond([&] { step(precision); }, a.steps, batch);
  };
  const double cpp = rate(nn::Precision::kFloat32), bf16 = rate(nn::Precision::kBf16);
  const double python = a.reference ? PythonReference(a, size, net, b) : 0;
  const auto tokens = net->text_encoder()->TokenIds(b.texts);
  const double flops =
      TrainingStepFlops(size, static_cast<double>(batch), static_cast<double>(a.frames),
                        static_cast<double>(tokens.size(1)), net->options().text);
  const double achieved = flops * cpp / static_cast<double>(batch) / 1e9,
               peak = SgemmGflops(size.dim);
  std::printf("%-6s %10lld %12.2f %12.2f %8.2f %11.1f %11.1f %8.0f%% %12.2f %9.2f\n",
              size.name.c_str(), static_cast<long long>(parameters), cpp, python,
              python > 0 ? cpp / python : 0.0, achieved, peak, 100 * achieved / peak, bf16,
              bf16 / cpp);
  std::fflush(stdout);
  // The profile is of the step the train stage runs when asked for bf16: float32 where this CPU
  // would emulate the bf16 products (plugins/common/precision.h).
  const nn::Precision profiled =
      nn::EffectivePrecision(nn::Precision::kBf16, nn::CpuHasNativeBf16());
  if (profile) Profile(a.profile, nn::PrecisionName(profiled), [&] { step(profiled); });
  return {1e3 * static_cast<double>(batch) / cpp, 1e3 * static_cast<double>(batch) / bf16};
}

// Milliseconds per call of `f`: the best of five rounds of `reps` calls after one warm-up call.
template <typename F>
double MsPerCall(F&& f, int reps) {
  f();
  double best = 1e30;
  for (int round = 0; round < 5; ++round) {
    const auto started = Clock::now();
    for (int k = 0; k < reps; ++k) f();
    best = std::min(best, 1e3 * Since(started) / reps);
  }
  return best;
}

// The fused kernels against LibTorch's operators on the same inputs at one size's training shape:
// DiT's tanh-GELU forward and backward over one block's MLP activation in bf16 (batch x (2 frames
// + 1) tokens x ff; LibTorch's route is the float32 kernel between two conversions, what the MDT
// ran before; `layers` calls a step), adaLN and the linears under bf16 autocast, clipping + AdamW
// over the net's parameters (one call), and attention's core and adaLN in float32. "of a step":
// what each saves, as a share of the step of its precision without the kernels of that precision
// (the steps above run them): a float32 kernel of the float32 step, a bf16 one of the bf16 step
// where this CPU has bf16 products (elsewhere the train stage runs bf16 as float32).
// A fused kernel (or ATen's linear) against the LibTorch route it replaces, ms per call fwd+bwd.
struct FusedRow {
  std::string name;
  double torch_ms, fused_ms;
  int64_t calls;      // per training step
  bool bf16 = true;   // a kernel of bf16 steps (else of float32 ones)
  bool both = false;  // of either
};

// The element-wise kernels: tanh-GELU and adaLN's modulated LayerNorm and gated residual.
void TimeElementwiseKernels(const Args& a, const Size& size, std::vector<FusedRow>& table) {
  const int64_t tokens = 2 * a.frames + 1, rows = a.batch * tokens;
  const std::string shape = std::to_string(tokens) + " x " + std::to_string(a.batch) + " x ";
  {
    const auto x = torch::randn({rows, size.ff}).to(torch::kBFloat16);
    const auto dy = torch::randn({rows, size.ff}).to(torch::kBFloat16);
    const auto gelu = [&](bool fused) {
      const auto xi = x.detach().requires_grad_();
      const auto y = fused ? nn::GeluTanhBf16(xi)
                           : torch::gelu(xi.to(torch::kFloat), "tanh").to(torch::kBFloat16);
      y.backward(dy);
    };
    table.push_back(
        {"tanh-GELU, bf16 [" + std::to_string(rows) + " x " + std::to_string(size.ff) + "]",
         MsPerCall([&] { gelu(false); }, 20), MsPerCall([&] { gelu(true); }, 20), size.layers});
  }
  {
    const auto x = torch::randn({rows, size.ff}), dy = torch::randn({rows, size.ff});
    const auto gelu = [&](bool fused) {
      const auto xi = x.detach().requires_grad_();
      const auto y = fused ? nn::GeluTanhFloat32(xi) : torch::gelu(xi, "tanh");
      y.backward(dy);
    };
    table.push_back(
        {"tanh-GELU, float32 [" + std::to_string(rows) + " x " + std::to_string(size.ff) + "]",
         MsPerCall([&] { gelu(false); }, 20), MsPerCall([&] { gelu(true); }, 20), size.layers,
         false});
  }
  for (const bool bf16 : {true, false}) {
    // adaLN around a sub-layer: a float32 stream, the modulation and the sub-layer's output [1, N,
    // d] in bf16 (a bf16 step; LibTorch's route ends in the cast to bf16 that the next linear makes
    // under autocast) or in float32 (a float32 step).
    const auto dtype = bf16 ? torch::kBFloat16 : torch::kFloat;
    const std::string what = (bf16 ? " [" : ", float32 [") + shape + std::to_string(size.dim) + "]";
    const auto x = torch::randn({tokens, a.batch, size.dim});
    const auto scale = torch::randn({1, a.batch, size.dim}).to(dtype);
    const auto shift = torch::randn({1, a.batch, size.dim}).to(dtype);
    const auto dy = torch::randn({tokens, a.batch, size.dim}).to(dtype);
    const auto modulate = [&](bool fused) {
      const auto xi = x.detach().requires_grad_();
      const auto si = scale.detach().requires_grad_(), bi = shift.detach().requires_grad_();
      const auto y =
          !fused ? (torch::layer_norm(xi, {size.dim}, {}, {}, 1e-6) * (1 + si) + bi).to(dtype)
          : bf16 ? nn::ModulatedLayerNormBf16(xi, si, bi, 1e-6)
                 : nn::ModulatedLayerNormFloat32(xi, si, bi, 1e-6);
      y.backward(dy);
    };
    table.push_back({"adaLN LN(x)(1+scale)+shift" + what, MsPerCall([&] { modulate(false); }, 20),
                     MsPerCall([&] { modulate(true); }, 20), 2 * size.layers + 1, bf16});
    const auto y = torch::randn({tokens, a.batch, size.dim}).to(dtype);
    const auto dh = torch::randn({tokens, a.batch, size.dim});
    const auto gated = [&](bool fused) {
      const auto xi = x.detach().requires_grad_();
      const auto gi = scale.detach().requires_grad_(), yi = y.detach().requires_grad_();
      const auto h = !fused ? xi + gi * yi
                     : bf16 ? nn::GatedResidualBf16(xi, gi, yi)
                            : nn::GatedResidualFloat32(xi, gi, yi);
      h.backward(dh);
    };
    table.push_back({"adaLN x + gate y" + what, MsPerCall([&] { gated(false); }, 20),
                     MsPerCall([&] { gated(true); }, 20), 2 * size.layers, bf16});
  }
}

// A DiT block's linears, clip + AdamW, and attention's float32 core.
void TimeMatrixKernels(const Args& a, const Size& size, std::vector<FusedRow>& table) {
  const int64_t tokens = 2 * a.frames + 1;
  // A DiT block's four linears under bf16 autocast: torch::nn::Linear::forward (matmul, then the
  // bias in a second pass) against ATen's linear (nn::ApplyLinear: one addmm).
  for (const auto& [in, out, what] :
       {std::tuple{size.dim, 3 * size.dim, "in_proj"}, std::tuple{size.dim, size.dim, "out_proj"},
        std::tuple{size.dim, size.ff, "fc1"}, std::tuple{size.ff, size.dim, "fc2"}}) {
    torch::nn::Linear layer(in, out);
    const auto x = torch::randn({tokens, a.batch, in}).to(torch::kBFloat16);
    const auto dy = torch::randn({tokens, a.batch, out}).to(torch::kBFloat16);
    const auto linear = [&](bool fused) {
      const auto xi = x.detach().requires_grad_();
      torch::Tensor y;
      {
        const nn::MixedPrecision autocast(nn::Precision::kBf16);
        y = fused ? nn::ApplyLinear(layer, xi) : layer->forward(xi);
      }
      y.backward(dy.to(y.scalar_type()));
    };
    table.push_back({std::string("linear ") + what + " " + std::to_string(in) + " -> " +
                         std::to_string(out) + ", bf16 autocast",
                     MsPerCall([&] { linear(false); }, 20), MsPerCall([&] { linear(true); }, 20),
                     size.layers});
  }
  {
    EditorNet net = Build(size);
    std::vector<torch::Tensor> params = net->parameters();
    for (auto& p : params) p.mutable_grad() = 1e-3 * torch::randn_like(p);
    const auto options = torch::optim::AdamWOptions(1e-4).weight_decay(0.01);
    torch::optim::AdamW theirs(params, options), ours(params, options);
    int64_t parameters = 0;
    for (const auto& p : params) parameters += p.numel();
    const auto libtorch_step = [&] {
      torch::nn::utils::clip_grad_norm_(params, 1.0);
      theirs.step();
    };
    table.push_back({"clip + AdamW, " + std::to_string(parameters) + " params",
                     MsPerCall(libtorch_step, 10),
                     MsPerCall([&] { (void)nn::AdamWStep(ours, 1.0); }, 10), 1, true, true});
  }
  {
    // Self-attention's core in float32 (the DiT blocks' and the condition encoder's, over the
    // source, separator and target tokens), from in_proj's output to out_proj's input: ATen's
    // route (the heads taken apart, baddbmm, softmax, bmm, the heads put back) against the fused
    // kernel, forward and backward, some keys ignored by padding.
    const int64_t head_dim = size.dim / size.heads;
    const auto qkv = torch::randn({tokens, a.batch, 3 * size.dim});
    const auto padding = torch::arange(tokens).view({1, -1}).ge(
        tokens - torch::arange(a.batch).remainder(a.frames / 2).view({-1, 1}));
    const auto dout = torch::randn({tokens, a.batch, size.dim});
    const auto attend = [&](bool fused) {
      const auto x = qkv.detach().requires_grad_();
      const auto out = fused ? nn::SelfAttentionFloat32(x, size.heads, padding, {})
                             : nn::SelfAttentionThroughAten(x, size.heads, padding, {});
      out.backward(dout);
    };
    table.push_back({"attention core, float32 [" + std::to_string(a.batch * size.heads) + " x " +
                         std::to_string(tokens) + " x " + std::to_string(head_dim) + "]",
                     MsPerCall([&] { attend(false); }, 10), MsPerCall([&] { attend(true); }, 10),
                     size.layers + size.cond_layers, false});
  }
}

void BenchFused(const Args& a, const Size& size, const StepMs& step_ms) {
  const bool native_bf16 = nn::CpuHasNativeBf16();
  using Row = FusedRow;
  std::vector<Row> table;
  torch::manual_seed(3);
  TimeElementwiseKernels(a, size, table);
  TimeMatrixKernels(a, size, table);
  // Whether a row runs in the step of a precision (bf16 = true: under bf16 autocast).
  const auto runs_in = [](const Row& row, bool bf16) { return row.both || row.bf16 == bf16; };
  const auto saved_in = [&](bool bf16) {
    double saved = 0;
    for (const Row& row : table)
      if (runs_in(row, bf16))
        saved += static_cast<double>(row.calls) * (row.torch_ms - row.fused_ms);
    return saved;
  };
  const double unfused32 = step_ms.float32 + saved_in(false),
               unfused16 = step_ms.bf16 + saved_in(true);
  std::printf(
      "\nfused kernels (plugins/common/fused.h) and ATen's linear, %s size, batch %lld, %lld "
      "frames, %lld thread(s): ms per call fwd+bwd, best of 5\n",
      size.name.c_str(), static_cast<long long>(a.batch), static_cast<long long>(a.frames),
      static_cast<long long>(a.threads));
  std::printf("%-52s %9s %9s %7s %6s %11s\n", "kernel", "LibTorch", "ours", "ratio", "calls",
              "of a step");
  for (const Row& row : table) {
    std::printf("%-52s %9.3f %9.3f %6.2fx %6lld ", row.name.c_str(), row.torch_ms, row.fused_ms,
                row.torch_ms / row.fused_ms, static_cast<long long>(row.calls));
    const double saved = static_cast<double>(row.calls) * (row.torch_ms - row.fused_ms);
    if (!row.bf16 || row.both)
      std::printf("%10.1f%%%s\n", 100 * saved / unfused32, row.both ? " (f32)" : "");
    else if (native_bf16)
      std::printf("%10.1f%%\n", 100 * saved / unfused16);
    else
      std::printf("%11s\n", "(bf16: none here)");
  }
  std::printf("float32 step %.1f ms with these; %.1f ms without (estimated): %.1f%% saved\n",
              step_ms.float32, unfused32, 100 * saved_in(false) / unfused32);
  if (native_bf16)
    std::printf("bf16 step %.1f ms with these; %.1f ms without (estimated): %.1f%% saved\n",
                step_ms.bf16, unfused16, 100 * saved_in(true) / unfused16);
  std::fflush(stdout);
}

// Editing: three guidance branches per motion in one batch; 150-frame sources and targets.
void BenchLatency(const Args& a, const Size& size, const std::vector<std::string>& texts) {
  std::printf(
      "\nediting latency, demo size, 150-frame source and target, three-way guidance, %lld "
      "thread(s)\n",
      static_cast<long long>(a.threads));
  std::printf("%-10s %6s %14s %16s %s\n", "sampler", "batch", "s per batch", "s per motion", "");
  torch::manual_seed(2);
  EditorNet net = Build(size);
  net->eval();
  torch::NoGradGuard no_grad;
  for (int64_t n : {int64_t{1}, int64_t{32}}) {
    std::vector<std::string> t3;
    for (int b = 0; b < 3; ++b) {
      for (int64_t i = 0; i < n; ++i) t3.push_back(texts[static_cast<size_t>(i % a.batch)]);
    }
    const auto src = torch::randn({150, n, kEditFeatureDim}).repeat({1, 3, 1});
    std::vector<int64_t> dt, ds;
    for (int b = 0; b < 3; ++b) {
      dt.insert(dt.end(), static_cast<size_t>(n), b < 2);
      ds.insert(ds.end(), static_cast<size_t>(n), b < 1);
    }
    Condition c{t3, src, torch::zeros({3 * n, 150}, torch::kBool),
                torch::tensor(dt).to(torch::kBool), torch::tensor(ds).to(torch::kBool)};
    const auto padding = torch::zeros({3 * n, 150}, torch::kBool);
    const Denoise denoise = [&](const torch::Tensor& xt, int64_t step) {
      const auto x0 =
          net->forward(xt.repeat({1, 3, 1}), torch::full({3 * n}, step, torch::kInt64), padding, c)
              .x0.chunk(3, 1);
      return GuideThreeWay(x0[0], x0[1], x0[2], 2.0, 2.0);
    };
    const CosineSchedule schedule(300);
    auto generator = at::make_generator<at::CPUGeneratorImpl>(1);
    // DDIM-50 in full; DDPM-300 timed over a 30-step schedule and scaled by 10 (each step is one
    // guided forward pass of the same cost) when the batch is 32.
    auto started = Clock::now();
    SampleDdim(schedule, {150, n, kEditFeatureDim}, 50, denoise, generator);
    const double ddim = Since(started);
    const int64_t measured = n == 1 ? 300 : 30;
    const CosineSchedule part(measured);
    started = Clock::now();
    SampleDdpm(part, {150, n, kEditFeatureDim}, denoise, generator);
    const double ddpm = Since(started) * 300.0 / static_cast<double>(measured);
    std::printf("%-10s %6lld %14.2f %16.3f\n", "DDIM-50", static_cast<long long>(n), ddim,
                ddim / static_cast<double>(n));
    std::printf("%-10s %6lld %14.2f %16.3f %s\n", "DDPM-300", static_cast<long long>(n), ddpm,
                ddpm / static_cast<double>(n), measured < 300 ? "(30 steps timed, x10)" : "");
    std::fflush(stdout);
  }
}

}  // namespace

int main(int argc, char** argv) {
  const std::string kernels = bench::UseNativeBlasKernels(argv);
  const std::optional<Args> args = ParseArgs(argc, argv);
  if (!args) {
    std::fprintf(stderr,
                 "usage: mdt_bench [--sizes demo,paper] [--steps K] [--threads T] [--batch N] "
                 "[--frames F] [--no-reference] [--no-latency] [--no-fused] [--profile N]\n");
    return 2;
  }
  nn::SetTorchThreads(static_cast<int>(args->threads));
  const std::vector<Size> all = {{"demo", 128, 2, 4, 4, 256}, {"paper", 512, 4, 8, 8, 1024}};
  std::printf(
      "MDT training step (diffusion x0 + similarity loss, backward, clip, AdamW), batch %lld, "
      "source and target up to %lld frames, %lld thread(s)\n",
      static_cast<long long>(args->batch), static_cast<long long>(args->frames),
      static_cast<long long>(args->threads));
  // The bf16 columns time LibTorch's bf16 products as they are on this CPU; the train stage
  // runs bf16 as float32 where they are emulated (plugins/common/precision.h).
  std::printf("bf16 products on this CPU: %s; OpenBLAS kernels: %s; LibTorch's: %s\n",
              nn::Bf16ProductsOnThisCpu(), kernels.c_str(), nn::AtenCapabilityInUse().c_str());
  std::printf("%-6s %10s %12s %12s %8s %11s %11s %9s %12s %9s\n", "size", "params", "C++ samp/s",
              "Py samp/s", "ratio", "C++ GFLOP/s", "sgemm peak", "of peak", "bf16 samp/s",
              "bf16/f32");
  const TrainBatch batch = MakeTrainBatch(*args);
  std::vector<std::pair<Size, StepMs>> step_ms;
  for (const Size& size : all) {
    if (args->sizes.find(size.name) != std::string::npos) {
      const bool profile = args->profile > 0 && step_ms.empty();
      step_ms.emplace_back(size, BenchTraining(*args, size, batch, profile));
    }
  }
  if (args->fused) {
    for (const auto& [size, ms] : step_ms) BenchFused(*args, size, ms);
  }
  if (args->latency) BenchLatency(*args, all[0], batch.texts);
  return 0;
}
