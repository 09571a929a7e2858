// The MDT editor's pieces: the noise schedule, guidance, adaLN-Zero, the similarity loss's masks,
// overfitting, editing length and finiteness, sampler determinism.
#include "../../plugins/mdt_editor/editor.h"

#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>

#include "../../plugins/common/fused.h"
#include "../../plugins/common/precision.h"
#include "../../plugins/mdt_editor/diffusion.h"
#include "../../plugins/mdt_editor/edit_data.h"
#include "../../plugins/mdt_editor/foot_contact.h"
#include "motionpipe/base/job_layout.h"
#include "motionpipe/features/motionfix207.h"
#include "motionpipe/formats/motionfix.h"

namespace motionpipe::mdt {
namespace {

TEST(Diffusion, CosineScheduleHasTheReferenceValues) {
  const CosineSchedule s(300);
  ASSERT_EQ(s.betas().size(), 300u);
  // alpha_bar(t) = f(t+1)/f(0) after step t, f(t) = cos^2(((t/T) + 0.008)/1.008 * pi/2)
  const auto f = [](double t) {
    const double c = std::cos((t / 300.0 + 0.008) / 1.008 * M_PI / 2);
    return c * c;
  };
  EXPECT_NEAR(s.alpha_bar()[0], f(1) / f(0), 1e-12);
  EXPECT_NEAR(s.alpha_bar()[149], f(150) / f(0), 1e-9);
  EXPECT_NEAR(s.betas()[0], 1 - f(1) / f(0), 1e-12);
  EXPECT_NEAR(s.betas()[299], 0.999, 1e-12);  // clipped at 0.999
  for (size_t t = 1; t < 300; ++t) EXPECT_LT(s.alpha_bar()[t], s.alpha_bar()[t - 1]);
  EXPECT_LT(s.alpha_bar()[299], 1e-6);
  // The fixed-small posterior variance beta (1 - abar_{t-1}) / (1 - abar_t)
  EXPECT_NEAR(s.PosteriorVariance(10),
              s.betas()[10] * (1 - s.alpha_bar()[9]) / (1 - s.alpha_bar()[10]), 1e-12);
}

TEST(Diffusion, QSampleAndPosteriorAreConsistent) {
  const CosineSchedule s(300);
  const auto x0 = torch::randn({5, 2, 3});
  const auto eps = torch::randn({5, 2, 3});
  const auto xt = s.QSample(x0, torch::tensor({0, 200}), eps);
  EXPECT_NEAR((xt.select(1, 1) - (std::sqrt(s.alpha_bar()[200]) * x0.select(1, 1) +
                                  std::sqrt(1 - s.alpha_bar()[200]) * eps.select(1, 1)))
                  .abs()
                  .max()
                  .item<double>(),
              0.0, 1e-5);
  // With the true x0 and eps, a DDIM step lands on the same trajectory: x_{t'} = sqrt(abar') x0 +
  // sqrt(1-abar') eps.
  const auto xt1 = s.QSample(x0, torch::tensor({200, 200}), eps);
  const auto next = s.DdimStep(x0, xt1, 200, 100);
  const auto expected =
      std::sqrt(s.alpha_bar()[100]) * x0 + std::sqrt(1 - s.alpha_bar()[100]) * eps;
  EXPECT_LT((next - expected).abs().max().item<double>(), 1e-4);
  EXPECT_EQ(DdimTimesteps(300, 50).front(), 299);
  EXPECT_EQ(DdimTimesteps(300, 50).back(), 0);
  EXPECT_EQ(DdimTimesteps(300, 50).size(), 50u);
}

TEST(Diffusion, ThreeWayGuidanceIsTheFormula) {
  const auto u = torch::tensor({1.0f}), cm = torch::tensor({2.0f}), ctm = torch::tensor({4.0f});
  // u + g_m (c_m - u) + g_t (c_tm - c_m) = 1 + 2 * 1 + 3 * 2
  EXPECT_FLOAT_EQ(GuideThreeWay(u, cm, ctm, 2.0, 3.0).item<float>(), 9.0f);
  // g = 1, 1 gives back the fully conditioned prediction.
  EXPECT_FLOAT_EQ(GuideThreeWay(u, cm, ctm, 1.0, 1.0).item<float>(), 4.0f);
}

TEST(Editor, AdaLnZeroBlocksStartAsTheIdentity) {
  torch::manual_seed(1);
  DiTBlock block(32, 4, 64);
  const auto x = torch::randn({7, 3, 32});
  const auto c = torch::randn({3, 32});
  EXPECT_TRUE(torch::equal(block->forward(x, c, torch::zeros({3, 7}, torch::kBool)), x));
}

EditorOptions Tiny(const std::string& variant, const std::string& aux = "classes") {
  nlohmann::json j = {{"variant", variant},
                      {"model",
                       {{"dim", 32},
                        {"cond_layers", 1},
                        {"layers", 2},
                        {"heads", 4},
                        {"ff", 64},
                        {"sim_hidden", 32},
                        {"dropout", 0.0},
                        {"text_encoder", {{"layers", 1}, {"vocab", 60}, {"dim", 32}}}}},
                      {"diffusion", {{"steps", 50}}}};
  j["aux"] = {{"mode", variant == "mdt" ? aux : "none"}};
  return EditorOptions::FromJson(j);
}

TEST(Editor, SimilarityLossCountsOnlyRealFramesWithACurveAndASource) {
  EditorOptions o = Tiny("mdt");
  o.class_weights = {1, 1, 1};
  // Two examples, 3 source frames; logits favour class 0 everywhere.
  auto logits = torch::zeros({2, 3, 3});
  logits.select(2, 0).fill_(2.0);
  auto classes = torch::tensor({{0, 1, -1}, {2, 2, 2}}, torch::kInt64);
  auto padding = torch::tensor({{0, 1, 0}, {0, 0, 0}}, torch::kInt64)
                     .to(torch::kBool);  // frame 1 of example 0 is padding
  const auto similarity = torch::zeros({2, 3});
  const double p0 = std::exp(2.0) / (std::exp(2.0) + 2);
  // Example 1's source dropped: only frame 0 of example 0 counts (class 0).
  auto out = SimilarityLoss(logits, classes, similarity, padding,
                            torch::tensor({0, 1}).to(torch::kBool), o);
  EXPECT_NEAR(out["aux"].item<double>(), -std::log(p0), 1e-6);
  EXPECT_NEAR(out["aux_accuracy"].item<double>(), 1.0, 1e-6);
  // Nothing dropped: frames (0,0) class 0 and example 1's three class-2 frames.
  out = SimilarityLoss(logits, classes, similarity, padding, torch::tensor({0, 0}).to(torch::kBool),
                       o);
  const double p2 = 1 / (std::exp(2.0) + 2);
  EXPECT_NEAR(out["aux"].item<double>(), (-std::log(p0) - 3 * std::log(p2)) / 4, 1e-6);
  EXPECT_NEAR(out["aux_accuracy"].item<double>(), 0.25, 1e-6);
  // The reference class weights [1, 0, 1] ignore the middle class.
  o.class_weights = {1, 0, 1};
  classes = torch::tensor({{1, 1, 1}, {0, 1, 1}}, torch::kInt64);
  out = SimilarityLoss(logits, classes, similarity, torch::zeros({2, 3}, torch::kBool),
                       torch::tensor({0, 0}).to(torch::kBool), o);
  EXPECT_NEAR(out["aux"].item<double>(), -std::log(p0), 1e-6);
}

struct TinyTriplets {
  std::vector<std::string> texts = {"raise the right arm", "walk faster", "bend the knees more"};
  torch::Tensor source, source_padding, target, target_padding;
  TinyTriplets() {
    torch::manual_seed(9);
    const auto t = torch::linspace(0, 1, 12).view({12, 1, 1});
    source = torch::sin(5.0 * t + torch::randn({1, 3, kEditFeatureDim}));
    target = source + 0.5 * torch::cos(3.0 * t + torch::randn({1, 3, kEditFeatureDim}));
    source_padding = torch::zeros({3, 12}, torch::kBool);
    target_padding = torch::zeros({3, 12}, torch::kBool);
    target_padding[2].narrow(0, 9, 3).fill_(true);
  }
};

// A tiny MDT (options set by `configure`) with every weight moved a little from its seeded start,
// in eval mode: adaLN-Zero and the zero output layer start the estimate at the source prior, and
// the moved weights make it depend on the condition. Options that add no parameter give the same
// weights with and without them.
EditorNet PerturbedMdt(const TinyTriplets& data, uint64_t seed,
                       const std::function<void(EditorOptions&)>& configure) {
  torch::manual_seed(seed);
  EditorOptions options = Tiny("mdt", "none");
  configure(options);
  EditorNet net(options);
  net->text_encoder()->Fit(data.texts);
  torch::NoGradGuard no_grad;
  for (auto& p : net->parameters()) p.add_(torch::randn_like(p) * 0.05);
  net->eval();
  return net;
}

TEST(Editor, EveryVariantOverfitsAFewTriplets) {
  for (const std::string variant :
       {"mdt", "tmed", "mdm", "mdt concat_source", "mdt concat_source text_tokens"}) {
    torch::manual_seed(2);
    EditorOptions options = Tiny(variant.substr(0, variant.find(' ')), "none");
    options.concat_source = variant.find("concat_source") != std::string::npos;
    options.text_tokens = variant.find("text_tokens") != std::string::npos;
    EditorNet net(options);
    const TinyTriplets data;
    net->text_encoder()->Fit(data.texts);
    const CosineSchedule schedule(50);
    torch::optim::AdamW optimizer(net->parameters(), torch::optim::AdamWOptions(2e-3));
    net->train();
    double first = 0, last = 0;
    for (int step = 0; step < 150; ++step) {
      // A fixed moderate noise level: the x0 loss of a denoiser that learned these targets falls.
      const auto t = torch::full({3}, 10, torch::kInt64);
      torch::manual_seed(step % 4);
      const auto xt = schedule.QSample(data.target, t, torch::randn_like(data.target));
      Condition c{data.texts,
                  options.variant == "mdm" ? torch::Tensor() : data.source,
                  data.source_padding,
                  {},
                  {}};
      const auto loss = GroupedMaskedMse(net->forward(xt, t, data.target_padding, c).x0,
                                         data.target, data.target_padding);
      optimizer.zero_grad();
      loss.backward();
      optimizer.step();
      if (step == 0) first = loss.item<double>();
      last = loss.item<double>();
    }
    EXPECT_LT(last, 0.2 * first) << variant << ": first " << first << " last " << last;
  }
}

// model.concat_source: the target tokens also read the aligned source frame (InstructPix2Pix's
// concatenation); where the source is dropped (guidance's unconditional branches) that half reads
// zeros, so the estimate does not depend on the source's content at all.
TEST(Editor, TheConcatenatedSourceChangesTheEstimateUnlessTheSourceIsDropped) {
  for (const std::string variant : {"mdt", "tmed"}) {
    torch::manual_seed(4);
    EditorOptions options = Tiny(variant, "none");
    options.concat_source = true;
    EditorNet net(options);
    const TinyTriplets data;
    net->text_encoder()->Fit(data.texts);
    net->eval();
    torch::NoGradGuard no_grad;
    const auto t = torch::full({3}, 5, torch::kInt64);
    const auto xt = data.target.clone();
    const auto estimate = [&](const torch::Tensor& source, bool dropped) {
      Condition c{data.texts, source, data.source_padding, torch::zeros({3}, torch::kBool),
                  torch::full({3}, dropped, torch::kBool)};
      return net->forward(xt, t, data.target_padding, c).x0;
    };
    const auto other = data.source + 1.0;
    EXPECT_GT((estimate(data.source, false) - estimate(other, false)).abs().max().item<double>(),
              1e-3)
        << variant;
    EXPECT_TRUE(torch::equal(estimate(data.source, true), estimate(other, true))) << variant;
  }
  nlohmann::json mdm = {{"variant", "mdm"}, {"model", {{"concat_source", true}}}};
  EXPECT_THROW(EditorNet{EditorOptions::FromJson(mdm)}, std::invalid_argument);
  EXPECT_TRUE(EditorOptions::FromJson({{"model", {{"concat_source", true}}}})
                  .ToJson()["model"]["concat_source"]
                  .get<bool>());
}

// model.text_tokens: the MDT's condition transformer also reads the text's tokens;
// model.dit_text_tokens: its DiT does (the condition transformer's outputs for them with
// text_tokens, their projections without). A triplet's estimate must not depend on the other texts
// of its batch (their lengths set the token count, and the source and target frames keep their
// positions after any number of tokens), the text must matter, and where it is dropped (guidance's
// branches without it) its words must not.
TEST(Editor, TextTokensReachTheMdtWithoutTyingATripletToItsBatch) {
  const TinyTriplets data;
  for (const auto& [text_tokens, dit_text_tokens] :
       std::vector<std::pair<bool, bool>>{{true, false}, {false, true}, {true, true}}) {
    SCOPED_TRACE("text_tokens " + std::to_string(text_tokens) + ", dit_text_tokens " +
                 std::to_string(dit_text_tokens));
    // The same weights with and without the DiT's tokens (the option adds no parameter).
    const auto make = [&](bool in_dit) {
      return PerturbedMdt(data, 6, [&](EditorOptions& o) {
        o.text_tokens = text_tokens;
        o.dit_text_tokens = in_dit;
      });
    };
    EditorNet net = make(dit_text_tokens);
    torch::NoGradGuard no_grad;
    const auto t = torch::full({3}, 5, torch::kInt64);
    const auto estimate_of = [&](EditorNet& of, const std::vector<std::string>& texts,
                                 bool dropped) {
      Condition c{texts, data.source, data.source_padding, torch::full({3}, dropped, torch::kBool),
                  torch::zeros({3}, torch::kBool)};
      return of->forward(data.target, t, data.target_padding, c).x0;
    };
    const auto estimate = [&](const std::vector<std::string>& texts, bool dropped) {
      return estimate_of(net, texts, dropped);
    };
    if (dit_text_tokens) {  // the tokens reach the DiT
      EditorNet without = make(false);
      EXPECT_GT((estimate(data.texts, false) - estimate_of(without, data.texts, false))
                    .abs()
                    .max()
                    .item<double>(),
                1e-4);
    }
    std::vector<std::string> longer = data.texts;
    longer[1] += " and then raise the right arm and bend the knees more";
    const auto base = estimate(data.texts, false), other = estimate(longer, false);
    EXPECT_LT((base.select(1, 0) - other.select(1, 0)).abs().max().item<double>(), 1e-5);
    EXPECT_GT((base.select(1, 1) - other.select(1, 1)).abs().max().item<double>(), 1e-4);
    EXPECT_LT((estimate(data.texts, true) - estimate(longer, true)).abs().max().item<double>(),
              1e-5);
  }
  for (const std::string key : {"text_tokens", "dit_text_tokens"}) {
    nlohmann::json tmed = {{"variant", "tmed"}, {"model", {{key, true}}}};
    EXPECT_THROW(EditorOptions::FromJson(tmed), std::invalid_argument) << key;
    EXPECT_TRUE(
        EditorOptions::FromJson({{"model", {{key, true}}}}).ToJson()["model"][key].get<bool>())
        << key;
  }
}

// model.time_token puts the timestep embedding first in the DiT's sequence (TMED's timestep
// token), model.dit_dropout drops in the DiT blocks as in the encoder layers. Neither adds a
// parameter, so the same weights with and without show each one's effect: the token changes the
// estimate, the dropout only in training.
TEST(Editor, TheDitsTimeTokenAndDropoutActWhereTheySay) {
  const TinyTriplets data;
  const auto make = [&](bool time_token, double dit_dropout) {
    return PerturbedMdt(data, 8, [&](EditorOptions& o) {
      o.time_token = time_token;
      o.dit_dropout = dit_dropout;
    });
  };
  torch::NoGradGuard no_grad;
  const auto estimate = [&](EditorNet& net) {
    const auto t = torch::tensor({5, 20, 40}, torch::kInt64);
    Condition c{data.texts, data.source, data.source_padding, torch::zeros({3}, torch::kBool),
                torch::zeros({3}, torch::kBool)};
    torch::manual_seed(1);
    return net->forward(data.target, t, data.target_padding, c).x0;
  };
  EditorNet plain = make(false, 0), timed = make(true, 0), dropping = make(false, 0.3);
  const auto base = estimate(plain);
  EXPECT_GT((estimate(timed) - base).abs().max().item<double>(), 1e-4);
  EXPECT_TRUE(torch::equal(estimate(dropping), base));  // eval: no dropout
  dropping->train();
  plain->train();  // the condition transformer's own dropout draws alike in both
  EXPECT_GT((estimate(dropping) - estimate(plain)).abs().max().item<double>(), 1e-4);
  for (const auto& [key, value] : std::vector<std::pair<std::string, nlohmann::json>>{
           {"time_token", true}, {"dit_dropout", 0.1}}) {
    nlohmann::json tmed = {{"variant", "tmed"}, {"model", {{key, value}}}};
    EXPECT_THROW(EditorOptions::FromJson(tmed), std::invalid_argument) << key;
    EXPECT_EQ(EditorOptions::FromJson({{"model", {{key, value}}}}).ToJson()["model"][key], value)
        << key;
  }
  EXPECT_THROW(EditorOptions::FromJson({{"model", {{"dit_dropout", 1.0}}}}), std::invalid_argument);
}

// model.trunk encoder: TMED's encoder layers over [timestep; text tokens; source; separator;
// noisy target] replace the DiT (no adaLN parameters), and the estimate still depends on the
// timestep, the text and the source, and not on the other texts of its batch.
TEST(Editor, TheEncoderTrunkReadsTimestepTextAndSource) {
  const TinyTriplets data;
  EditorNet net = PerturbedMdt(data, 10, [](EditorOptions& o) { o.trunk = "encoder"; });
  for (const auto& item : net->named_parameters())
    EXPECT_EQ(item.key().find("adaLN"), std::string::npos) << item.key();
  torch::NoGradGuard no_grad;
  const auto estimate = [&](const std::vector<std::string>& texts, const torch::Tensor& source,
                            int64_t step) {
    Condition c{texts, source, data.source_padding, torch::zeros({3}, torch::kBool),
                torch::zeros({3}, torch::kBool)};
    return net->forward(data.target, torch::full({3}, step, torch::kInt64), data.target_padding, c)
        .x0;
  };
  std::vector<std::string> longer = data.texts;
  longer[1] += " and then raise the right arm and bend the knees more";
  const auto base = estimate(data.texts, data.source, 5);
  const auto other = estimate(longer, data.source, 5);
  EXPECT_LT((base.select(1, 0) - other.select(1, 0)).abs().max().item<double>(), 1e-5);
  EXPECT_GT((base.select(1, 1) - other.select(1, 1)).abs().max().item<double>(), 1e-4);
  EXPECT_GT((estimate(data.texts, data.source, 40) - base).abs().max().item<double>(), 1e-4);
  EXPECT_GT((estimate(data.texts, data.source + 1.0, 5) - base).abs().max().item<double>(), 1e-4);
  EXPECT_THROW(EditorOptions::FromJson({{"model", {{"trunk", "unet"}}}}), std::invalid_argument);
  EXPECT_THROW(EditorOptions::FromJson({{"variant", "tmed"}, {"model", {{"trunk", "encoder"}}}}),
               std::invalid_argument);
}

// Issue 15: training in bf16 (plugins/common/precision.h). Under the guard the matrix products run
// in bfloat16 while the weights and their gradients stay float32, the guard restores autocast's
// state, and the MDT's loss and gradients on a batch agree with float32's (a broken cast, or
// autocast left on outside the guard, fails here).
TEST(Editor, Bf16AutocastKeepsFloat32WeightsAndTheLossAndGradientsOfFloat32) {
  EXPECT_EQ(nn::ParsePrecision("bf16", "params.precision"), nn::Precision::kBf16);
  EXPECT_EQ(nn::ParsePrecision("float32", "params.precision"), nn::Precision::kFloat32);
  try {
    nn::ParsePrecision("half", "params.precision");
    ADD_FAILURE() << "half accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("params.precision must be float32 or bf16, not 'half'"),
              std::string::npos)
        << e.what();
  }
  torch::nn::Linear linear(8, 4);
  const auto x = torch::randn({3, 8});
  {
    const nn::MixedPrecision outer(nn::Precision::kBf16);
    {
      const nn::MixedPrecision inner(nn::Precision::kBf16);
      EXPECT_EQ(linear(x).scalar_type(), torch::kBFloat16);
    }
    EXPECT_TRUE(at::autocast::is_cpu_enabled());  // the inner guard restores the outer state
    EXPECT_EQ(linear(x).scalar_type(), torch::kBFloat16);
  }
  EXPECT_FALSE(at::autocast::is_cpu_enabled());
  EXPECT_EQ(linear(x).scalar_type(), torch::kFloat32);
  {
    const nn::MixedPrecision off(nn::Precision::kFloat32);
    EXPECT_EQ(linear(x).scalar_type(), torch::kFloat32);
  }

  // A trained-a-little MDT (at initialisation adaLN-Zero makes the output trivial), then one
  // batch's loss and gradients in both precisions.
  torch::manual_seed(3);
  EditorNet net(Tiny("mdt", "none"));
  const TinyTriplets data;
  net->text_encoder()->Fit(data.texts);
  const CosineSchedule schedule(50);
  torch::optim::AdamW optimizer(net->parameters(), torch::optim::AdamWOptions(2e-3));
  net->train();
  const auto t = torch::full({3}, 10, torch::kInt64);
  const auto noise = torch::randn_like(data.target);
  const Condition c{data.texts, data.source, data.source_padding, {}, {}};
  const auto loss_of = [&](nn::Precision precision) {
    const nn::MixedPrecision autocast(precision);
    const auto xt = schedule.QSample(data.target, t, noise);
    return GroupedMaskedMse(net->forward(xt, t, data.target_padding, c).x0, data.target,
                            data.target_padding);
  };
  for (int step = 0; step < 30; ++step) {
    optimizer.zero_grad();
    loss_of(nn::Precision::kFloat32).backward();
    optimizer.step();
  }
  net->eval();  // no dropout: both passes see the same network
  const auto gradient = [&](nn::Precision precision) {
    optimizer.zero_grad();
    const auto loss = loss_of(precision);
    EXPECT_EQ(loss.scalar_type(), torch::kFloat32);
    loss.backward();
    std::vector<torch::Tensor> flat;
    for (const auto& p : net->parameters()) {
      EXPECT_EQ(p.scalar_type(), torch::kFloat32);
      if (p.grad().defined()) {
        EXPECT_EQ(p.grad().scalar_type(), torch::kFloat32);
        flat.push_back(p.grad().reshape({-1}).clone());
      }
    }
    return std::make_pair(loss.item<double>(), torch::cat(flat));
  };
  const auto [loss32, grad32] = gradient(nn::Precision::kFloat32);
  const auto [loss16, grad16] = gradient(nn::Precision::kBf16);
  EXPECT_NEAR(loss16, loss32, 0.02 * loss32);
  EXPECT_NE(loss16, loss32);  // the products did run in bf16
  const double cosine =
      (grad16 * grad32).sum().item<double>() / (grad16.norm() * grad32.norm()).item<double>();
  EXPECT_GT(cosine, 0.99);
}

// A trainer asked for bf16 runs it only where the CPU multiplies bf16 natively (AVX512-BF16 or
// AMX); elsewhere LibTorch's emulated bf16 products cost many times float32's (25x on a Zen 3
// EPYC), so it runs float32. float32 stays float32 everywhere. The detector agrees with the
// kernel's view of the CPU (/proc/cpuinfo's flags, where Linux provides them).
TEST(Editor, Bf16RunsOnlyWhereTheCpuMultipliesBf16Natively) {
  EXPECT_EQ(nn::EffectivePrecision(nn::Precision::kBf16, true), nn::Precision::kBf16);
  EXPECT_EQ(nn::EffectivePrecision(nn::Precision::kBf16, false), nn::Precision::kFloat32);
  EXPECT_EQ(nn::EffectivePrecision(nn::Precision::kFloat32, true), nn::Precision::kFloat32);
  EXPECT_EQ(nn::EffectivePrecision(nn::Precision::kFloat32, false), nn::Precision::kFloat32);
  std::ifstream cpuinfo("/proc/cpuinfo");
  std::string line, flags;
  while (std::getline(cpuinfo, line)) {
    if (line.rfind("flags", 0) == 0) {
      flags = line + " ";
      break;
    }
  }
  if (flags.empty()) GTEST_SKIP() << "no /proc/cpuinfo flags to compare with";
  const bool listed = (flags.find(" avx512_bf16 ") != std::string::npos &&
                       flags.find(" avx512f ") != std::string::npos) ||
                      flags.find(" amx_bf16 ") != std::string::npos;
  EXPECT_EQ(nn::CpuHasNativeBf16(), listed) << flags;
}

// DiT's tanh-GELU under bf16 is the float32 function rounded once (the fused kernel, whose own
// test compares it with LibTorch's float32 kernel): nearer the exact values than LibTorch's bf16
// kernel, whose intermediates are rounded (which is also 2.4 times slower).
TEST(Editor, Bf16TanhGeluIsTheFloat32FunctionRoundedOnce) {
  torch::manual_seed(5);
  const auto x = (3 * torch::randn({4096})).to(torch::kBFloat16).requires_grad_();
  const auto y = GeluTanh(x);
  EXPECT_EQ(y.scalar_type(), torch::kBFloat16);
  EXPECT_TRUE(torch::equal(y, nn::GeluTanhBf16(x.detach())));
  const auto exact = torch::gelu(x.detach().to(torch::kFloat64), "tanh");
  const auto error = [&](const torch::Tensor& v) {
    return (v.to(torch::kFloat64) - exact).abs().mean().item<double>();
  };
  EXPECT_LT(error(y.detach()), error(torch::gelu(x.detach(), "tanh")));
  // The gradient reaches x, of bf16, close to the float64 derivative.
  const auto g = torch::ones_like(y);
  const auto dx = torch::autograd::grad({y}, {x}, {g})[0];
  EXPECT_EQ(dx.scalar_type(), torch::kBFloat16);
  const auto xd = x.detach().to(torch::kFloat64).requires_grad_();
  const auto dxd =
      torch::autograd::grad({torch::gelu(xd, "tanh")}, {xd}, {torch::ones_like(xd)})[0];
  EXPECT_LT((dx.to(torch::kFloat64) - dxd).abs().max().item<double>(), 0.02);
  // float32 takes the fused float32 loop, other dtypes the plain kernel.
  const auto f = torch::randn({16});
  EXPECT_TRUE(torch::equal(GeluTanh(f), nn::GeluTanhFloat32(f)));
  const auto f64 = f.to(torch::kFloat64);
  EXPECT_TRUE(torch::equal(GeluTanh(f64), torch::gelu(f64, "tanh")));
}

// adaLN-Zero under bf16 autocast (a float32 stream, bf16 modulation and sub-layer output) takes the
// bf16 fused kernels, the float32 model the float32 ones (their own tests compare them with
// float64), other dtypes LibTorch's operators; the routes agree to bf16's precision.
TEST(Editor, AdaLnTakesTheFusedKernelsOfItsPrecision) {
  torch::manual_seed(6);
  const auto x = torch::randn({7, 3, 16});
  const auto scale = 0.3 * torch::randn({1, 3, 16}), shift = 0.3 * torch::randn({1, 3, 16});
  const auto y = torch::randn({7, 3, 16});
  const auto s16 = scale.to(torch::kBFloat16), b16 = shift.to(torch::kBFloat16),
             y16 = y.to(torch::kBFloat16);
  const auto modulated = Modulate(x, s16, b16);
  EXPECT_EQ(modulated.scalar_type(), torch::kBFloat16);
  EXPECT_TRUE(torch::equal(modulated, nn::ModulatedLayerNormBf16(x, s16, b16, 1e-6)));
  const auto plain = Modulate(x, scale, shift);
  EXPECT_EQ(plain.scalar_type(), torch::kFloat32);
  EXPECT_TRUE(torch::equal(plain, nn::ModulatedLayerNormFloat32(x, scale, shift, 1e-6)));
  EXPECT_TRUE(torch::allclose(plain, torch::layer_norm(x, {16}, {}, {}, 1e-6) * (1 + scale) + shift,
                              1e-5, 1e-5));
  const auto x64 = x.to(torch::kFloat64), scale64 = scale.to(torch::kFloat64),
             shift64 = shift.to(torch::kFloat64);
  EXPECT_TRUE(torch::equal(Modulate(x64, scale64, shift64),
                           torch::layer_norm(x64, {16}, {}, {}, 1e-6) * (1 + scale64) + shift64));
  const auto same = torch::layer_norm(x, {16}, {}, {}, 1e-6) * (1 + s16.to(torch::kFloat)) +
                    b16.to(torch::kFloat);
  EXPECT_LT((modulated.to(torch::kFloat) - same).abs().max().item<double>(),
            0.01 * same.abs().max().item<double>());

  const auto gated = GatedResidual(x, s16, y16);
  EXPECT_EQ(gated.scalar_type(), torch::kFloat32);
  EXPECT_TRUE(torch::equal(gated, nn::GatedResidualBf16(x, s16, y16)));
  EXPECT_TRUE(torch::equal(GatedResidual(x, scale, y), nn::GatedResidualFloat32(x, scale, y)));
  EXPECT_TRUE(torch::allclose(GatedResidual(x, scale, y), x + scale * y, 1e-6, 1e-6));
  const auto y64 = y.to(torch::kFloat64);
  EXPECT_TRUE(torch::equal(GatedResidual(x64, scale64, y64), x64 + scale64 * y64));
  EXPECT_TRUE(
      torch::allclose(gated, x + s16.to(torch::kFloat) * y16.to(torch::kFloat), 1e-6, 1e-6));
}

// Issue 15: target positions were offset by the batch's longest source (and TMED's by its longest
// text), so an example met offsets at edit time (batches sorted by length) that training (batches
// nearly always holding a max_frames source) never showed it. A prediction must not depend on the
// other examples of its batch.
TEST(Editor, AnExamplesPredictionDoesNotDependOnItsBatch) {
  for (const std::string variant : {"mdt", "tmed", "mdm"}) {
    torch::manual_seed(4);
    EditorNet net(Tiny(variant));
    net->text_encoder()->Fit(
        {"raise the right arm", "walk faster and then turn around to the left twice"});
    net->eval();
    torch::NoGradGuard no_grad;
    // Example 0: 9-frame source and target, a short text. Example 1: 20 frames, a long text.
    const auto source = torch::randn({20, 2, kEditFeatureDim});
    const auto xt = torch::randn({20, 2, kEditFeatureDim});
    auto source_padding = torch::zeros({2, 20}, torch::kBool);
    source_padding[0].narrow(0, 9, 11).fill_(true);
    const auto target_padding = source_padding.clone();
    const auto t = torch::tensor({45, 20}, torch::kInt64);  // of the 50 steps
    const std::vector<std::string> texts = {"raise the right arm",
                                            "walk faster and then turn around to the left twice"};
    const bool with_source = variant != "mdm";
    Condition both{texts, with_source ? source : torch::Tensor(), source_padding, {}, {}};
    const auto batched = net->forward(xt, t, target_padding, both).x0.select(1, 0).narrow(0, 0, 9);
    Condition alone{{texts[0]},
                    with_source ? source.narrow(0, 0, 9).narrow(1, 0, 1) : torch::Tensor(),
                    torch::zeros({1, 9}, torch::kBool),
                    {},
                    {}};
    const auto single = net->forward(xt.narrow(0, 0, 9).narrow(1, 0, 1), t.narrow(0, 0, 1),
                                     torch::zeros({1, 9}, torch::kBool), alone)
                            .x0.select(1, 0);
    EXPECT_LT((batched - single).abs().max().item<double>(), 1e-4) << variant;
  }
}

// Issue 15: the adaLN condition added the post-LayerNorm text token (norm about sqrt(d)) to the
// timestep embedding (norm a few units), drowning the timestep. At initialisation the text's term
// must be no larger than the timestep's (DiT starts its class embeddings at N(0, 0.02)).
TEST(Editor, TheTextDoesNotDrownTheTimestepInAdaLn) {
  torch::manual_seed(5);
  nlohmann::json j = {{"variant", "mdt"},
                      {"model",
                       {{"dim", 128},
                        {"cond_layers", 1},
                        {"layers", 1},
                        {"heads", 4},
                        {"ff", 64},
                        {"sim_hidden", 32}}}};
  EditorNet net(EditorOptions::FromJson(j));
  torch::NoGradGuard no_grad;
  const auto t = torch::randint(300, {64}, torch::kInt64);
  // A post-LayerNorm token: entries of unit spread, norm about sqrt(d).
  const auto text = torch::layer_norm(torch::randn({64, 128}), {128});
  const double time_norm = net->TimeEmbedding(t).norm(2, 1).mean().item<double>();
  const double text_norm = net->TextCondition(text).norm(2, 1).mean().item<double>();
  EXPECT_GT(time_norm, 0.0);
  EXPECT_LE(text_norm, time_norm) << "text " << text_norm << " timestep " << time_norm;
  EXPECT_GT(text_norm, 0.0);  // small, not absent: the text still reaches adaLN and gets gradient
}

TEST(Diffusion, TheSnrShiftMovesLogSnrByTwoLogK) {
  const CosineSchedule plain(300), shifted(300, 4.0);
  const auto logit = [](double a) { return std::log(a / (1 - a)); };
  for (size_t t : {0, 50, 150, 250, 299}) {
    EXPECT_NEAR(logit(shifted.alpha_bar()[t]), logit(plain.alpha_bar()[t]) - 2 * std::log(4.0),
                1e-6)
        << t;
    // The betas reproduce the shifted alpha_bar as their running product.
    double product = 1;
    for (size_t k = 0; k <= t; ++k) product *= 1 - shifted.betas()[k];
    EXPECT_NEAR(product, shifted.alpha_bar()[t], 1e-9 + 1e-6 * shifted.alpha_bar()[t]) << t;
  }
  EXPECT_EQ(plain.betas(), CosineSchedule(300, 1.0).betas());
  EXPECT_THROW(CosineSchedule(300, 0.5), std::invalid_argument);
}

// Min-SNR-gamma: min(SNR_t, gamma) divided by its mean over the steps, so the weights average 1
// under uniform steps; the clean end weighs gamma / mean, the noisiest almost nothing; and the
// weighted x0 loss is the per-example losses' weighted mean.
TEST(Diffusion, MinSnrWeightsClampTheSignalToNoiseRatioAndAverageOne) {
  const CosineSchedule schedule(300, 1.0);
  const auto all = torch::arange(300, torch::kInt64);
  const auto w = MinSnrWeights(schedule, all, 5.0);
  EXPECT_NEAR(w.mean().item<double>(), 1.0, 1e-5);
  double mean = 0;
  for (double abar : schedule.alpha_bar()) mean += std::min(abar / (1 - abar), 5.0) / 300;
  EXPECT_NEAR(w[0].item<double>(), 5.0 / mean, 1e-4);  // SNR_0 is far above 5
  const double abar = schedule.alpha_bar()[200];
  ASSERT_LT(abar / (1 - abar), 5.0);
  EXPECT_NEAR(w[200].item<double>(), abar / (1 - abar) / mean, 1e-4);
  EXPECT_LT(w[299].item<double>(), 1e-3);
  for (int64_t t = 1; t < 300; ++t) EXPECT_LE(w[t].item<double>(), w[t - 1].item<double>() + 1e-6);
  // Two examples, errors 1 and 3 on every real entry, weights 2 and 0.5: (2 + 1.5) / 2.
  const auto target = torch::zeros({4, 2, kEditFeatureDim});
  auto prediction = target.clone();
  prediction.select(1, 0).fill_(1.0);
  prediction.select(1, 1).fill_(std::sqrt(3.0));
  auto padding = torch::zeros({2, 4}, torch::kBool);
  padding[1][3] = true;
  EXPECT_NEAR(GroupedMaskedMse(prediction, target, padding).item<double>(), 2.0, 1e-5);
  EXPECT_NEAR(
      GroupedMaskedMse(prediction, target, padding, torch::tensor({2.0f, 0.5f})).item<double>(),
      1.75, 1e-5);
  EXPECT_THROW(EditorOptions::FromJson({{"diffusion", {{"min_snr_gamma", -1}}}}),
               std::invalid_argument);
}

TEST(Diffusion, TrainingStepsFollowTheirDensity) {
  // Power 0 is the reference's uniform draw, the same numbers as torch::randint under one seed.
  auto a = at::make_generator<at::CPUGeneratorImpl>(7),
       b = at::make_generator<at::CPUGeneratorImpl>(7);
  for (int i = 0; i < 50; ++i)
    EXPECT_EQ(SampleTrainingStep(300, 0, a), torch::randint(300, {1}, b).item<int64_t>());
  // Power 1: density proportional to t, so P(t >= 250) = 1 - (250/300)^2 = 0.306 (uniform: 0.167)
  // and the mean is 2/3 of 300, less the half step of the floor.
  auto g = at::make_generator<at::CPUGeneratorImpl>(11);
  const int n = 40000;
  int noisy = 0;
  double sum = 0;
  for (int i = 0; i < n; ++i) {
    const int64_t t = SampleTrainingStep(300, 1, g);
    ASSERT_TRUE(t >= 0 && t < 300);
    noisy += t >= 250;
    sum += static_cast<double>(t);
  }
  EXPECT_NEAR(static_cast<double>(noisy) / n, 1 - (250.0 / 300) * (250.0 / 300), 0.01);
  EXPECT_NEAR(sum / n, 200 - 0.5, 1.5);
  EXPECT_THROW(EditorOptions::FromJson({{"diffusion", {{"step_density_power", -1}}}}),
               std::invalid_argument);
}

TEST(Diffusion, PreconditioningIsKarrasForThisSchedule) {
  const CosineSchedule schedule(300);
  const double sd = 0.5;
  const auto [skip, out] =
      schedule.Preconditioning(torch::tensor({0, 150, 299}, torch::kInt64), sd);
  for (int k = 0; k < 2; ++k) {
    const int64_t t = k == 0 ? 0 : 150;
    const double abar = schedule.alpha_bar()[static_cast<size_t>(t)];
    const double sigma2 = (1 - abar) / abar;
    // c_skip x~ with x~ = x_t / sqrt(abar); c_out = sigma sd / sqrt(sigma^2 + sd^2).
    EXPECT_NEAR(skip[0][k][0].item<double>(), sd * sd / (sigma2 + sd * sd) / std::sqrt(abar), 1e-5)
        << t;
    EXPECT_NEAR(out[0][k][0].item<double>(), std::sqrt(sigma2) * sd / std::sqrt(sigma2 + sd * sd),
                1e-5)
        << t;
  }
  // At the last step x_t is nearly pure noise: no skip, c_out -> sd; finite.
  EXPECT_LT(skip[0][2][0].item<double>(), 1e-3);
  EXPECT_NEAR(out[0][2][0].item<double>(), sd, 1e-3);
}

// Issue 15: at width 128 the plain x0 head rebuilt every target frame from the trunk and could not
// reproduce even a clean target (trained MDT: x0 MSE 0.023 at t = 0, where x_t itself gives
// 0.0002); the sampler turned that floor into jitter. With the EDM preconditioning an untrained
// editor already passes a nearly clean target through, whatever its variant.
TEST(Editor, TheEdmPreconditioningPassesANearlyCleanTargetThrough) {
  for (const std::string variant : {"mdt", "tmed", "mdm"}) {
    for (const std::string preconditioning : {"edm", "x0"}) {
      torch::manual_seed(6);
      EditorOptions o = Tiny(variant, "none");
      o.preconditioning = preconditioning;
      o.diffusion_steps = 300;  // the reference schedule: at t = 0 the noise is of spread 0.006
      EditorNet net(o);
      const TinyTriplets data;
      net->text_encoder()->Fit(data.texts);
      net->eval();
      torch::NoGradGuard no_grad;
      const CosineSchedule schedule(o.diffusion_steps);
      const auto target = 0.5 * data.target;  // the normalised features' spread
      const auto t = torch::zeros({3}, torch::kInt64);
      const auto xt = schedule.QSample(target, t, torch::randn_like(target));
      Condition c{data.texts,
                  variant == "mdm" ? torch::Tensor() : data.source,
                  data.source_padding,
                  {},
                  {}};
      const double mse = GroupedMaskedMse(net->forward(xt, t, data.target_padding, c).x0, target,
                                          data.target_padding)
                             .item<double>();
      if (preconditioning == "edm") {
        EXPECT_LT(mse, 1e-3) << variant;
      } else {
        EXPECT_GT(mse, 1e-2) << variant << ": the plain head starts far from the clean target";
      }
    }
  }
}

// Issue 15: the "source" parameterisation x0 = aligned source + F. The source is resampled to the
// target's length by floor(i L_s / L_t); the untrained editor returns exactly that (F starts at 0),
// and nothing of the source where it is dropped (classifier-free guidance's unconditional branch).
TEST(Editor, TheSourcePreconditioningStartsAsACopyOfTheAlignedSource) {
  // A 4-frame source against an 8-frame target (stretched) and a 6-frame source against a 3-frame
  // target (shrunk); the sources' values are their frame numbers.
  auto source = torch::arange(6, torch::kFloat32).view({6, 1, 1}).expand({6, 2, 2}).clone();
  auto source_padding = torch::zeros({2, 6}, torch::kBool);
  source_padding[0].narrow(0, 4, 2).fill_(true);
  auto target_padding = torch::zeros({2, 8}, torch::kBool);
  target_padding[1].narrow(0, 3, 5).fill_(true);
  const auto aligned = AlignSource(source, source_padding, target_padding);
  ASSERT_EQ(aligned.sizes(), (std::vector<int64_t>{8, 2, 2}));
  const std::vector<float> stretched = {0, 0, 1, 1, 2, 2, 3, 3}, shrunk = {0, 2, 4};
  for (int64_t i = 0; i < 8; ++i) EXPECT_EQ(aligned[i][0][1].item<float>(), stretched[i]) << i;
  for (int64_t i = 0; i < 3; ++i) EXPECT_EQ(aligned[i][1][0].item<float>(), shrunk[i]) << i;

  for (const std::string variant : {"mdt", "tmed"}) {
    torch::manual_seed(7);
    EditorOptions o = Tiny(variant, "none");
    o.preconditioning = "source";
    EditorNet net(o);
    const TinyTriplets data;
    net->text_encoder()->Fit(data.texts);
    net->eval();
    torch::NoGradGuard no_grad;
    const auto xt = torch::randn_like(data.target);
    const auto t = torch::tensor({49, 20, 0}, torch::kInt64);
    Condition c{data.texts, data.source, data.source_padding, {}, {}};
    auto x0 = net->forward(xt, t, data.target_padding, c).x0;
    const auto expected = AlignSource(data.source, data.source_padding, data.target_padding);
    EXPECT_LT((x0 - expected).abs().max().item<double>(), 1e-6) << variant;
    // Example 2's target is 9 frames of a 12-frame source: frame 8 takes source frame 10.
    EXPECT_LT((x0[8][2] - data.source[10][2]).abs().max().item<double>(), 1e-6) << variant;
    c.drop_source = torch::tensor({0, 1, 0}).to(torch::kBool);
    x0 = net->forward(xt, t, data.target_padding, c).x0;
    EXPECT_EQ(x0.select(1, 1).abs().max().item<double>(), 0.0) << variant;
    EXPECT_LT((x0.select(1, 0) - data.source.select(1, 0)).abs().max().item<double>(), 1e-6);
  }
  // An option this version does not know is an error naming it, not silently ignored.
  nlohmann::json misspelt = Tiny("mdt", "none").ToJson();
  misspelt["diffusion"]["learned_skp"] = true;
  try {
    EditorOptions::FromJson(misspelt);
    ADD_FAILURE() << "a misspelt key was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("diffusion.learned_skp: unknown key"), std::string::npos)
        << e.what();
  }
  EditorOptions mdm = Tiny("mdm", "none");
  mdm.preconditioning = "source";
  EXPECT_THROW(EditorOptions::FromJson(mdm.ToJson()), std::invalid_argument);
}

// Issue 15: the learned skip starts at the Wiener gain (about 1 at t = 0, so a nearly clean target
// passes through where the plain head starts far from it) and is a parameter the loss trains.
TEST(Editor, TheLearnedSkipPassesANearlyCleanTargetAndLearns) {
  for (const std::string preconditioning : {"x0", "source"}) {
    torch::manual_seed(8);
    EditorOptions o = Tiny("mdt", "none");
    o.preconditioning = preconditioning;
    o.learned_skip = true;
    o.diffusion_steps = 300;
    EditorNet net(o);
    const TinyTriplets data;
    net->text_encoder()->Fit(data.texts);
    const CosineSchedule schedule(o.diffusion_steps);
    const auto target = 0.5 * data.target;
    Condition c{data.texts, data.source, data.source_padding, {}, {}};
    const auto t0 = torch::zeros({3}, torch::kInt64);
    net->eval();
    {
      torch::NoGradGuard no_grad;
      const auto xt = schedule.QSample(target, t0, torch::randn_like(target));
      const double mse = GroupedMaskedMse(net->forward(xt, t0, data.target_padding, c).x0, target,
                                          data.target_padding)
                             .item<double>();
      EXPECT_LT(mse, 5e-3) << preconditioning;
    }
    // At t = 150 the gain is trained: a few steps move the parameter row of that step only.
    net->train();
    torch::optim::AdamW optimizer(net->parameters(), torch::optim::AdamWOptions(1e-2));
    const auto t = torch::full({3}, 150, torch::kInt64);
    for (int step = 0; step < 5; ++step) {
      const auto xt = schedule.QSample(target, t, torch::randn_like(target));
      const auto loss = GroupedMaskedMse(net->forward(xt, t, data.target_padding, c).x0, target,
                                         data.target_padding);
      optimizer.zero_grad();
      loss.backward();
      optimizer.step();
    }
    const auto skip = net->named_parameters()["skip"];
    EXPECT_GT(skip[150].abs().max().item<double>(), 1e-3) << preconditioning;
    EXPECT_LT(skip[20].abs().max().item<double>(), 1e-9) << preconditioning;  // untouched (decay 0)
  }
  EditorOptions edm = Tiny("mdt", "none");
  edm.preconditioning = "edm";
  edm.learned_skip = true;
  EXPECT_THROW(EditorNet{edm}, std::invalid_argument);
}

// Issue 15: diffusion.components runs the diffusion on the principal components of the frame. On
// frames of known rank the code is exact, orthonormal, of spread sigma_data per axis and
// sign-fixed; the net reads and writes k coordinates, and with the source prior the untrained
// editor still copies its (projected) source.
TEST(Editor, PrincipalComponentsCodeTheFrameExactlyAtItsRank) {
  torch::manual_seed(11);
  // 4,000 frames of rank 5 in 207 columns, spreads 2, 1, 0.5, 0.25, 0.1 along random axes.
  const auto axes = std::get<0>(torch::linalg_qr(torch::randn({kEditFeatureDim, 5})));
  const auto spreads = torch::tensor({2.0, 1.0, 0.5, 0.25, 0.1}, torch::kFloat32);
  const auto frames = torch::matmul(torch::randn({4000, 5}) * spreads, axes.t());
  const auto centred = frames - frames.mean(0);
  const auto covariance = torch::matmul(centred.t(), centred) / 3999.0;
  double explained = 0;
  auto [basis, scale] = PrincipalFrameBasis(covariance, 5, 0.5, &explained);
  ASSERT_EQ(basis.sizes(), (std::vector<int64_t>{kEditFeatureDim, 5}));
  EXPECT_NEAR(explained, 1.0, 1e-4);
  EXPECT_LT((torch::matmul(basis.t(), basis) - torch::eye(5)).abs().max().item<double>(), 1e-4);
  const auto z = torch::matmul(centred, basis) / scale;
  EXPECT_LT((z.std(0) - 0.5).abs().max().item<double>(), 0.01);
  EXPECT_LT((torch::matmul(z * scale, basis.t()) - centred).abs().max().item<double>(), 1e-4);
  // Each axis's entry of largest magnitude is positive.
  EXPECT_TRUE((basis.gather(0, basis.abs().argmax(0).unsqueeze(0)) > 0).all().item<bool>());
  // Fewer components keep the largest spreads: (4 + 1) / (4 + 1 + 0.25 + 0.0625 + 0.01).
  PrincipalFrameBasis(covariance, 2, 0.5, &explained);
  EXPECT_NEAR(explained, 5.0 / 5.3225, 0.01);

  EditorOptions o = Tiny("mdt", "none");
  o.preconditioning = "source";
  o.components = 5;
  EditorNet net(o);
  EXPECT_EQ(net->diffusion_dim(), 5);
  EXPECT_NEAR(net->FitFrameBasis(covariance), 1.0, 1e-4);
  const TinyTriplets data;
  net->text_encoder()->Fit(data.texts);
  net->eval();
  torch::NoGradGuard no_grad;
  // Sources in the frames' span: the code round-trips them.
  const auto source = torch::matmul(torch::randn({12, 3, 5}) * spreads, axes.t());
  EXPECT_LT((net->Decode(net->Encode(source)) - source).abs().max().item<double>(), 1e-4);
  Condition c{data.texts, source, data.source_padding, {}, {}};
  const auto xt = torch::randn({12, 3, 5});
  const auto x0 =
      net->forward(xt, torch::tensor({49, 20, 0}, torch::kInt64), data.target_padding, c).x0;
  ASSERT_EQ(x0.sizes(), (std::vector<int64_t>{12, 3, 5}));
  const auto aligned = AlignSource(source, data.source_padding, data.target_padding);
  EXPECT_LT((net->Decode(x0) - aligned).abs().max().item<double>(), 1e-4);
  // Unwhitened, the code is the orthonormal projection: coordinates keep the frame's scale.
  EditorOptions projection = o;
  projection.whiten = false;
  EditorNet projected(projection);
  projected->FitFrameBasis(covariance);
  EXPECT_NEAR(projected->Encode(source).pow(2).sum().item<double>(),
              source.pow(2).sum().item<double>(), 1e-3 * source.pow(2).sum().item<double>());
  // The range is checked.
  nlohmann::json too_many = o.ToJson();
  too_many["diffusion"]["components"] = kEditFeatureDim + 1;
  EXPECT_THROW(EditorOptions::FromJson(too_many), std::invalid_argument);
  EditorOptions plain = Tiny("mdt", "none");
  EditorNet identity(plain);
  EXPECT_THROW(identity->FitFrameBasis(covariance), std::logic_error);
  EXPECT_TRUE(torch::equal(identity->Encode(source), source));
}

// SDEdit's sampler: from `start` noised to t_start, DDIM with an exact x0 ends on that x0; with a
// denoiser that returns its input's scaled mean it stays near `start`, nearer the lower t_start.
TEST(Diffusion, SamplingFromANoisedStartEndsOnTheEstimateAndKeepsTheStart) {
  const CosineSchedule schedule(300);
  torch::manual_seed(4);
  const auto start = torch::randn({20, 2, 7}) * 0.5;
  const auto target = torch::randn({20, 2, 7}) * 0.5;
  auto generator = at::make_generator<at::CPUGeneratorImpl>(1);
  const Denoise exact = [&](const torch::Tensor&, int64_t) { return target; };
  const auto x = SampleDdimFromNoised(schedule, start, 150, 10, exact, generator);
  EXPECT_LT((x - target).abs().max().item<double>(), 1e-4);
  // The posterior mean of data N(start, 0) is start itself: the sample returns to it exactly.
  const Denoise keep = [&](const torch::Tensor&, int64_t) { return start; };
  for (int64_t t_start : {30, 150, 299}) {
    const auto y = SampleDdimFromNoised(schedule, start, t_start, 20, keep, generator);
    EXPECT_LT((y - start).abs().max().item<double>(), 1e-4) << t_start;
  }
  // A denoiser that trusts x_t: the lower t_start, the nearer the sample stays to the start.
  const Denoise trust = [&](const torch::Tensor& xt, int64_t t) {
    return xt / std::sqrt(schedule.alpha_bar()[static_cast<size_t>(t)]);
  };
  double previous = 0;
  for (int64_t t_start : {10, 60, 150}) {
    auto g = at::make_generator<at::CPUGeneratorImpl>(2);
    const double d = (SampleDdimFromNoised(schedule, start, t_start, 10, trust, g) - start)
                         .pow(2)
                         .mean()
                         .item<double>();
    EXPECT_GT(d, previous) << t_start;
    previous = d;
  }
  EXPECT_THROW(SampleDdimFromNoised(schedule, start, 300, 10, exact, generator),
               std::invalid_argument);
}

TEST(Editor, SamplingGivesTheRequestedLengthFiniteAndRepeatsUnderASeed) {
  torch::manual_seed(3);
  EditorNet net(Tiny("mdt"));
  const TinyTriplets data;
  net->text_encoder()->Fit(data.texts);
  net->eval();
  const CosineSchedule schedule(50);
  Condition c{{data.texts[0], data.texts[0], data.texts[0]},
              data.source.narrow(1, 0, 1).repeat({1, 3, 1}),
              data.source_padding.narrow(0, 0, 1).repeat({3, 1}),
              torch::tensor({1, 1, 0}).to(torch::kBool),
              torch::tensor({1, 0, 0}).to(torch::kBool)};
  const Denoise denoise = [&](const torch::Tensor& xt, int64_t t) {
    const auto x0 = net->forward(xt.repeat({1, 3, 1}), torch::full({3}, t, torch::kInt64),
                                 torch::zeros({3, 17}, torch::kBool), c)
                        .x0.chunk(3, 1);
    return GuideThreeWay(x0[0], x0[1], x0[2], 2.0, 2.0);
  };
  const auto run = [&](uint64_t seed, bool ddim) {
    auto generator = at::make_generator<at::CPUGeneratorImpl>(seed);
    return ddim ? SampleDdim(schedule, {17, 1, kEditFeatureDim}, 10, denoise, generator)
                : SampleDdpm(schedule, {17, 1, kEditFeatureDim}, denoise, generator);
  };
  for (bool ddim : {false, true}) {
    const auto a = run(5, ddim), b = run(5, ddim), other = run(6, ddim);
    EXPECT_EQ(a.sizes(), (std::vector<int64_t>{17, 1, kEditFeatureDim}));
    EXPECT_TRUE(torch::isfinite(a).all().item<bool>());
    EXPECT_TRUE(torch::equal(a, b));
    EXPECT_FALSE(torch::equal(a, other));
  }
}

// Issue 15: a feature column constant over the training motions (a joint the corpus never turns)
// had std 0 and divided any other motion's deviation by 2e-5: the CMU edit's inputs reached 1e4.
// Such a column keeps std 1; the others get their own.
TEST(Editor, ConstantFeatureColumnsKeepUnitScale) {
  const std::string dir = ::testing::TempDir() + "/constant_columns";
  std::filesystem::create_directories(dir + "/motionfix");
  std::vector<Triplet> triplets;
  for (int i = 0; i < 4; ++i) {
    Triplet t;
    t.id = "t" + std::to_string(i);
    t.text = "raise the arm";
    t.split = "train";
    for (Motion* m : {&t.source, &t.target}) {
      *m = Motion::Rest(30, 30, 0.9);
      for (int64_t f = 0; f < 30; ++f) {
        m->poses[static_cast<size_t>(f * 66 + 16 * 3 + 2)] =
            0.02f * static_cast<float>(f + i);  // the left shoulder turns
        // and the body walks, the target faster
        m->trans[static_cast<size_t>(f * 3)] =
            (m == &t.target ? 0.04f : 0.03f) * static_cast<float>(f);
      }
    }
    triplets.push_back(std::move(t));
  }
  ASSERT_TRUE(WriteTriplets(dir + "/motionfix/triplets-00000.npz", triplets).ok());
  EditDataOptions options;
  options.filter = "none";
  const EditDataset data(options, {dir});
  const auto [mean, stddev] = data.ComputeStats();
  // Local rotation of joint j (1..21): columns 15 + 6 (j - 1) ... ; the right knee (5) never turns.
  const int64_t knee = 15 + 6 * (5 - 1), shoulder = 15 + 6 * (16 - 1);
  EXPECT_FLOAT_EQ(stddev[knee].item<float>(), 1.0f);
  EXPECT_FLOAT_EQ(stddev[knee + 4].item<float>(), 1.0f);
  // A turn about z moves four of the six 6D entries (cos and sin terms); they get their own spread.
  int moving = 0;
  for (int k = 0; k < 6; ++k) {
    const double sd = stddev[shoulder + k].item<float>();
    if (sd > 1e-3 && sd < 0.5) ++moving;
  }
  EXPECT_EQ(moving, 4);
  // Each item's id and motions at the data's rate (mdt_probe --write decodes to them).
  ASSERT_EQ(data.size(), 4);
  for (int64_t i = 0; i < 4; ++i) {
    EXPECT_EQ(data.Id(i), "t" + std::to_string(i));
    const Motion target = data.SideMotionOf(i, false);
    EXPECT_EQ(target.num_frames(), 30);
    EXPECT_FLOAT_EQ(target.poses[static_cast<size_t>(29 * 66 + 16 * 3 + 2)],
                    0.02f * static_cast<float>(29 + i));
    EXPECT_FLOAT_EQ(target.trans[static_cast<size_t>(29 * 3)], 0.04f * 29);
    EXPECT_FLOAT_EQ(data.SideMotionOf(i, true).trans[static_cast<size_t>(29 * 3)], 0.03f * 29);
  }
}

// Issue 15's fitting diagnostic: data.limit keeps the split's first triplets in file and row order
// (with filter: none), the ones an `edit` stage with the same split and limit edits; validation
// (val_split: train) reads the same ones.
TEST(Editor, DataLimitKeepsTheSplitsFirstTripletsInFileAndRowOrder) {
  const std::string dir = ::testing::TempDir() + "/data_limit";
  std::filesystem::create_directories(dir + "/motionfix");
  for (int file = 0; file < 2; ++file) {
    std::vector<Triplet> triplets;
    for (int r = 0; r < 3; ++r) {
      Triplet t;
      t.id = "f" + std::to_string(file) + "r" + std::to_string(r);
      t.text = "walk";
      t.split = r == 1 ? "test" : "train";
      t.source = t.target = Motion::Rest(30, 30, 0.9);
      triplets.push_back(std::move(t));
    }
    // Written second-file-first: the order is the files' names, not the order they came.
    ASSERT_TRUE(WriteTriplets(dir + "/motionfix/triplets-0000" + std::to_string(1 - file) + ".npz",
                              triplets)
                    .ok());
  }
  plugin::DataContext context;
  context.input_dirs = {dir};
  context.config = {{"filter", "none"}, {"limit", 3}, {"val_split", "train"}};
  for (const std::string split : {"train", "val"}) {
    context.split = split;
    const EditDataset data(EditDataOptions::FromContext(context), context.input_dirs);
    ASSERT_EQ(data.size(), 3) << split;
    EXPECT_EQ(data.Id(0), "f1r0");  // triplets-00000 holds the second file written
    EXPECT_EQ(data.Id(1), "f1r2");
    EXPECT_EQ(data.Id(2), "f0r0");
  }
  context.split = "train";
  context.config["limit"] = 9;  // more than there are: all four training triplets
  EXPECT_EQ(EditDataset(EditDataOptions::FromContext(context), context.input_dirs).size(), 4);
  context.config["limit"] = 0;  // the default: all
  EXPECT_EQ(EditDataset(EditDataOptions::FromContext(context), context.input_dirs).size(), 4);
  context.config["limit"] = -1;
  EXPECT_THROW(EditDataOptions::FromContext(context), std::invalid_argument);
}

// With filter: none the editor reads a corpus input's triplets once. A train stage's input
// directories are the corpus's result and its tasks, and the result's files are the tasks' shards
// again (hard links): reading every directory trained on each triplet twice and, since the
// filter's curves name the result's files, gave half the rows a similarity curve.
TEST(Editor, DataWithoutFilterReadsACorpusResultNotItsShardsAgain) {
  namespace fs = std::filesystem;
  const std::string corpus = ::testing::TempDir() + "/data_corpus";
  fs::remove_all(corpus);
  std::vector<std::string> input_dirs = {corpus + "/result"};
  fs::create_directories(corpus + "/result/motionfix");
  for (int task = 0; task < 2; ++task) {
    std::vector<Triplet> triplets(3);
    for (size_t r = 0; r < triplets.size(); ++r) {
      triplets[r].id = "task" + std::to_string(task) + "r" + std::to_string(r);
      triplets[r].text = "walk";
      triplets[r].split = "train";
      triplets[r].source = triplets[r].target = Motion::Rest(30, 30, 0.9);
    }
    const std::string name = "/motionfix/triplets-0000" + std::to_string(task) + ".npz";
    const std::string dir = layout::TaskDir(corpus, task);
    fs::create_directories(dir + "/motionfix");
    ASSERT_TRUE(WriteTriplets(dir + name, triplets).ok());
    fs::create_hard_link(dir + name, corpus + "/result" + name);
    input_dirs.push_back(dir);
  }
  plugin::DataContext context;
  context.input_dirs = input_dirs;
  context.config = {{"filter", "none"}};
  context.split = "train";
  const EditDataset data(EditDataOptions::FromContext(context), context.input_dirs);
  ASSERT_EQ(data.size(), 6);
  for (int64_t i = 0; i < data.size(); ++i)
    EXPECT_EQ(data.Id(i), "task" + std::to_string(i / 3) + "r" + std::to_string(i % 3)) << i;
  fs::remove_all(corpus);
}

// Issue 15: the network's frame rate (EditorOptions::fps). Training motions and edit sources come
// to it by keeping every k-th frame (with their stored joints), edits go back to the rate and the
// length asked for.
TEST(Editor, TheNetworkRateKeepsEveryKthFrameAndEditsComeBackAtTheAskedLength) {
  Motion m = Motion::Rest(31, 30, 0.9);
  std::vector<float> joints(31 * kNumJoints * 3);
  for (int64_t f = 0; f < 31; ++f) {
    m.trans[static_cast<size_t>(f * 3)] = 0.03f * static_cast<float>(f);  // walks along x
    for (int64_t k = 0; k < kNumJoints * 3; ++k)
      joints[static_cast<size_t>(f * kNumJoints * 3 + k)] = static_cast<float>(f);
  }
  const AtNetworkRate at = ToNetworkRate(m, joints.data(), 10);
  EXPECT_EQ(at.step, 3);
  ASSERT_EQ(at.motion.num_frames(), 11);  // frames 0, 3, ..., 30
  EXPECT_EQ(at.motion.fps, 10);
  ASSERT_EQ(at.joints.size(), 11U * kNumJoints * 3);
  for (int64_t f = 0; f < 11; ++f) {
    EXPECT_FLOAT_EQ(at.motion.trans[static_cast<size_t>(f * 3)], 0.03f * static_cast<float>(3 * f));
    EXPECT_EQ(at.joints[static_cast<size_t>(f * kNumJoints * 3 + 5)], static_cast<float>(3 * f));
  }
  // The data's own rate, or none asked: unchanged. 20 fps (1.5 frames each): interpolated, joints
  // left to forward kinematics.
  for (double fps : {0.0, 30.0}) {
    const AtNetworkRate same = ToNetworkRate(m, joints.data(), fps);
    EXPECT_EQ(same.motion.num_frames(), 31);
    EXPECT_EQ(same.step, 1);
    EXPECT_EQ(same.joints, joints);
  }
  const AtNetworkRate twenty = ToNetworkRate(m, joints.data(), 20);
  EXPECT_DOUBLE_EQ(twenty.step, 1.5);
  EXPECT_EQ(twenty.motion.num_frames(), 21);
  EXPECT_TRUE(twenty.joints.empty());
  EXPECT_NEAR(twenty.motion.trans[3], 0.045, 1e-6);  // halfway between frames 1 and 2
  // Network frames that cover a length, and the way back: exactly the frames asked for.
  EXPECT_EQ(FramesCovering(31, 30, 10), 11);
  EXPECT_EQ(FramesCovering(32, 30, 10), 12);
  EXPECT_EQ(FramesCovering(32, 30, 0), 32);
  EXPECT_EQ(FramesCovering(32, 30, 30), 32);
  const Motion back = ResampleToFrames(at.motion, 30, 31).value();
  ASSERT_EQ(back.num_frames(), 31);
  EXPECT_EQ(back.fps, 30);
  for (int64_t f = 0; f < 31; ++f)
    EXPECT_NEAR(back.trans[static_cast<size_t>(f * 3)], 0.03 * static_cast<double>(f), 1e-5) << f;
  const Motion longer = ResampleToFrames(at.motion, 30, 33).value();  // repeats the last frame
  ASSERT_EQ(longer.num_frames(), 33);
  EXPECT_FLOAT_EQ(longer.trans[32 * 3], longer.trans[30 * 3]);
  EXPECT_FALSE(ResampleToFrames(Motion{}, 30, 3).ok());

  // The training data at the network's rate: 30-frame clips at 30 fps become 10 frames at 10 fps.
  const std::string dir = ::testing::TempDir() + "/network_rate";
  std::filesystem::create_directories(dir + "/motionfix");
  std::vector<Triplet> triplets(2);
  for (int i = 0; i < 2; ++i) {
    triplets[i].id = "t" + std::to_string(i);
    triplets[i].text = "walk";
    triplets[i].split = "train";
    triplets[i].source = triplets[i].target = Motion::Rest(30, 30, 0.9);
  }
  ASSERT_TRUE(WriteTriplets(dir + "/motionfix/triplets-00000.npz", triplets).ok());
  EditDataOptions options;
  options.filter = "none";
  options.fps = 10;
  EditDataset data(options, {dir});
  const auto [mean, stddev] = data.ComputeStats();
  data.SetStats(mean, stddev);
  const auto batch = data.Get({0, 1}, 0);
  EXPECT_EQ(batch.tensors.at("source").size(0), 10);
  EXPECT_EQ(batch.tensors.at("target").size(0), 10);
  EXPECT_THROW(EditorOptions::FromJson({{"fps", -10}}), std::invalid_argument);
}

TEST(Editor, PartColumnsPartitionTheFeature) {
  const auto columns = PartColumns();
  // Every column belongs to exactly one part (pelvis position columns 141:144 to global).
  EXPECT_TRUE(columns.to(torch::kInt64).sum(0).eq(1).all().item<bool>());
  EXPECT_EQ(columns[0].sum().item<int64_t>(), 15 + 3);
}

}  // namespace
}  // namespace motionpipe::mdt

namespace motionpipe::mdt {
namespace {

TEST(Editor, GroupedMseAveragesPerGroupThenOverGroups) {
  // One example, 2 real frames + 1 padded; error 1 on every column of group 0 (3 columns) in one
  // frame: group 0's mean = 3 / (2 * 3) = 0.5, the other four groups 0 -> loss 0.5 / 5.
  auto prediction = torch::zeros({3, 1, kEditFeatureDim});
  const auto target = torch::zeros({3, 1, kEditFeatureDim});
  prediction[0][0].narrow(0, 0, 3).fill_(1.0);
  prediction[2][0].fill_(100.0);  // padding: ignored
  auto padding = torch::zeros({1, 3}, torch::kBool);
  padding[0][2] = true;
  EXPECT_NEAR(GroupedMaskedMse(prediction, target, padding).item<double>(), 0.1, 1e-7);
}

TEST(Editor, TheLegWeightMultipliesTheLegsColumnsErrorsAlone) {
  // Error 1 on the left knee's first rotation column (joint 4) and on the left elbow's (joint 18),
  // one real frame: body_pose's mean is (w + 1) / 126, the other groups 0, over 5 groups.
  auto prediction = torch::zeros({1, 1, kEditFeatureDim});
  const auto target = torch::zeros({1, 1, kEditFeatureDim});
  prediction[0][0][15 + 6 * 3] = 1.0;
  prediction[0][0][15 + 6 * 17] = 1.0;
  const auto padding = torch::zeros({1, 1}, torch::kBool);
  for (double w : {1.0, 4.0}) {
    EXPECT_NEAR(
        GroupedMaskedMse(prediction, target, padding, {}, LegColumnWeights(w)).item<double>(),
        (w + 1) / 126 / 5, 1e-7)
        << "legs " << w;
  }
  // The legs' columns are both legs' rotations and joint positions: 2 x (4 joints x 6 + 4 x 3).
  EXPECT_EQ(LegColumnWeights(3).eq(3).sum().item<int64_t>(), 2 * (4 * 6 + 4 * 3));
  EXPECT_EQ(EditorOptions::FromJson({{"loss", {{"legs", 4}}}}).leg_weight, 4);
  EXPECT_EQ(EditorOptions::FromJson({{"loss", {{"legs", 4}}}}).ToJson()["loss"]["legs"], 4);
  EXPECT_THROW(EditorOptions::FromJson({{"loss", {{"legs", 0}}}}), std::invalid_argument);
}

TEST(Editor, VelocityLossSeesJitterNotOffsets) {
  torch::manual_seed(8);
  const auto target = torch::randn({10, 2, kEditFeatureDim});
  auto padding = torch::zeros({2, 10}, torch::kBool);
  padding[1].narrow(0, 6, 4).fill_(true);
  // A constant offset: x0 error, no velocity error.
  EXPECT_NEAR(VelocityMse(target + 0.3, target, padding).item<double>(), 0.0, 1e-10);
  EXPECT_GT(GroupedMaskedMse(target + 0.3, target, padding).item<double>(), 0.08);
  // Alternating +-a per frame: every difference is off by 2a, squared 4a^2.
  const auto sign = torch::tensor({1., -1., 1., -1., 1., -1., 1., -1., 1., -1.})
                        .to(torch::kFloat32)
                        .view({10, 1, 1});
  EXPECT_NEAR(VelocityMse(target + 0.1 * sign, target, padding).item<double>(), 0.04, 1e-5);
  // Differences that touch a padded frame do not count: garbage there changes nothing.
  auto garbage = target.clone();
  garbage.select(1, 1).narrow(0, 6, 4).add_(100.0);
  EXPECT_NEAR(VelocityMse(garbage, target, padding).item<double>(), 0.0, 1e-8);
}

// A walk that turns, leans and swings its legs, with the pelvis bobbing: every term of the feet's
// kinematics (pelvis velocity, tilt, heading change, hips, knees, ankles) moves.
Motion TurningWalk(int64_t frames) {
  Motion m = Motion::Rest(frames, 30, 0.9);
  for (int64_t f = 0; f < frames; ++f) {
    const double t = static_cast<double>(f) / 30;
    m.SetTranslation(f, Vec3{0.8 * t, 0.3 * t * t, 0.9 + 0.03 * std::sin(9 * t)});
    m.SetLocalRotation(f, 0, RotZ(0.7 * t) * RotX(kPi / 2) * RotZ(0.1 * std::sin(3 * t)));
    for (const int side : {0, 1}) {
      const double phase = 6 * t + kPi * side;
      m.SetLocalRotation(f, 1 + side, RotX(0.5 * std::sin(phase)) * RotZ(0.05 * side));
      m.SetLocalRotation(f, 4 + side, RotX(0.6 * (1 + std::cos(phase))));
      m.SetLocalRotation(f, 7 + side, RotX(0.2 * std::sin(phase)) * RotY(0.1));
    }
  }
  return m;
}

torch::Tensor FeatureTensor(const Motion& m) {
  FeatureMatrix f = EncodeMotionFix207(Skeleton::Smpl22(), m);
  return torch::from_blob(f.data.data(), {f.rows, 1, f.cols}, torch::kFloat32).clone();
}

// Issue 15 (plausibility): the foot-contact loss's kinematics read the columns decoding reads and
// reproduce the feet of the motion's forward kinematics. A displacement expressed in a heading
// frame keeps its length and its height, so both are compared with the world's.
TEST(Editor, FootDisplacementsAreTheForwardKinematicsFeet) {
  const Motion m = TurningWalk(24);
  const auto d = FootDisplacements(FeatureTensor(m));
  ASSERT_EQ(d.sizes(), (std::vector<int64_t>{23, 1, 4, 3}));
  const std::vector<float> joints = ComputeJoints(Skeleton::Smpl22(), m);
  double largest = 0;
  for (int64_t i = 1; i < 24; ++i) {
    int k = 0;
    for (const int joint : {7, 10, 8, 11}) {
      double world[3], length = 0;
      for (int c = 0; c < 3; ++c) {
        world[c] = joints[static_cast<size_t>((i * kNumJoints + joint) * 3 + c)] -
                   joints[static_cast<size_t>(((i - 1) * kNumJoints + joint) * 3 + c)];
        length += world[c] * world[c];
      }
      const auto ours = d[i - 1][0][k++];
      EXPECT_NEAR(ours.norm().item<double>(), std::sqrt(length), 2e-5) << "frame " << i;
      EXPECT_NEAR(ours[2].item<double>(), world[2], 2e-5) << "frame " << i;
      largest = std::max(largest, std::sqrt(length));
    }
  }
  EXPECT_GT(largest, 0.02);  // the feet do move (at 30 fps, 0.6 m/s)
}

// The features of a rest pose standing still and of the same pose sliding forward at 0.5 m/s
// (30 fps), [frames, 1, 207] each.
std::pair<torch::Tensor, torch::Tensor> StandingAndSliding(int64_t frames) {
  const Motion standing = Motion::Rest(frames, 30, 0.9);
  Motion sliding = standing;
  for (int64_t f = 0; f < frames; ++f) sliding.SetTranslation(f, Vec3{0.5 * f / 30.0, 0, 0.9});
  return {FeatureTensor(standing), FeatureTensor(sliding)};
}

// L_foot penalises the prediction's feet only where the target's stand still, in (m/s)^2, and not
// on padded frames; its gradient reaches the pelvis velocity and the legs, not the arms or the
// derived positions.
TEST(Editor, FootContactLossPenalisesFeetThatMoveWhereTheTargetsStand) {
  const int64_t frames = 16;
  const auto [stand, slide] = StandingAndSliding(frames);
  const auto none = torch::zeros({1, frames}, torch::kBool);
  EXPECT_NEAR(FootContactLoss(stand, stand, none, 30, 0.15).item<double>(), 0.0, 1e-8);
  // Every foot slides at 0.5 m/s where the target stands: 0.25 (m/s)^2.
  EXPECT_NEAR(FootContactLoss(slide, stand, none, 30, 0.15).item<double>(), 0.25, 1e-3);
  // Where the target's feet move (faster than the contact speed) nothing is asked of them.
  EXPECT_NEAR(FootContactLoss(stand, slide, none, 30, 0.15).item<double>(), 0.0, 1e-8);
  // Read as 10-fps frames, the same per-frame step is a third of the speed.
  EXPECT_NEAR(FootContactLoss(slide, stand, none, 10, 0.15).item<double>(), 0.25 / 9, 1e-4);
  // A prediction that slides only on padded frames is not penalised.
  auto padding = torch::zeros({1, frames}, torch::kBool);
  padding[0].narrow(0, 8, frames - 8).fill_(true);
  auto late = stand.clone();
  late.narrow(0, 8, frames - 8).copy_(slide.narrow(0, 8, frames - 8));
  EXPECT_NEAR(FootContactLoss(late, stand, padding, 30, 0.15).item<double>(), 0.0, 1e-8);
  EXPECT_GT(FootContactLoss(late, stand, none, 30, 0.15).item<double>(), 0.01);
  // The gradient: the walk's frames against a standing target.
  auto walk = FeatureTensor(TurningWalk(frames)).requires_grad_(true);
  FootContactLoss(walk, stand, none, 30, 0.15).backward();
  const torch::Tensor g = walk.grad().abs().sum(std::vector<int64_t>{0, 1});
  EXPECT_GT(g.narrow(0, 0, 3).sum().item<double>(), 0);            // pelvis velocity
  EXPECT_GT(g.narrow(0, 3, 6).sum().item<double>(), 0);            // heading-free orientation
  EXPECT_GT(g.narrow(0, 9, 6).sum().item<double>(), 0);            // heading change
  EXPECT_GT(g.narrow(0, 15, 6).sum().item<double>(), 0);           // left hip (joint 1)
  EXPECT_GT(g.narrow(0, 15 + 6 * 6, 6).sum().item<double>(), 0);   // left ankle (joint 7)
  EXPECT_EQ(g.narrow(0, 15 + 6 * 15, 6).sum().item<double>(), 0);  // left shoulder (joint 16)
  EXPECT_EQ(g.narrow(0, 141, 66).sum().item<double>(), 0);         // derived positions
}

// L_vel on the feet compares the prediction's foot velocities with the target's in (m/s)^2 on every
// real frame pair, moving or standing; its gradient reaches the pelvis velocity and the legs only.
TEST(Editor, FootVelocityLossComparesTheFeetsVelocitiesOnEveryRealFramePair) {
  const int64_t frames = 16;
  const auto [stand, slide] = StandingAndSliding(frames);
  const auto walk = FeatureTensor(TurningWalk(frames));
  const auto none = torch::zeros({1, frames}, torch::kBool);
  EXPECT_NEAR(FootVelocityLoss(walk, walk, none, 30).item<double>(), 0.0, 1e-6);
  // Every foot 0.5 m/s off the target's, whichever moves: 0.25 (m/s)^2 both ways (L_foot asks
  // nothing of a foot whose target moves).
  EXPECT_NEAR(FootVelocityLoss(slide, stand, none, 30).item<double>(), 0.25, 1e-3);
  EXPECT_NEAR(FootVelocityLoss(stand, slide, none, 30).item<double>(), 0.25, 1e-3);
  EXPECT_NEAR(FootContactLoss(stand, slide, none, 30, 0.15).item<double>(), 0.0, 1e-8);
  // Read as 10-fps frames, the same per-frame step is a third of the speed.
  EXPECT_NEAR(FootVelocityLoss(slide, stand, none, 10).item<double>(), 0.25 / 9, 1e-4);
  // Padded frame pairs do not count, and the mean is over the real ones only.
  auto padding = torch::zeros({1, frames}, torch::kBool);
  padding[0].narrow(0, 8, frames - 8).fill_(true);
  auto late = stand.clone();
  late.narrow(0, 8, frames - 8).copy_(slide.narrow(0, 8, frames - 8));
  EXPECT_NEAR(FootVelocityLoss(late, stand, padding, 30).item<double>(), 0.0, 1e-8);
  EXPECT_NEAR(FootVelocityLoss(slide, stand, padding, 30).item<double>(), 0.25, 1e-3);
  // The gradient reaches the columns decoding reads for the feet, and no others; none reaches the
  // target.
  auto prediction = walk.clone().requires_grad_(true);
  auto target = stand.clone().requires_grad_(true);
  FootVelocityLoss(prediction, target, none, 30).backward();
  const torch::Tensor g = prediction.grad().abs().sum(std::vector<int64_t>{0, 1});
  EXPECT_GT(g.narrow(0, 0, 3).sum().item<double>(), 0);            // pelvis velocity
  EXPECT_GT(g.narrow(0, 9, 6).sum().item<double>(), 0);            // heading change
  EXPECT_GT(g.narrow(0, 15 + 6 * 3, 6).sum().item<double>(), 0);   // left knee (joint 4)
  EXPECT_EQ(g.narrow(0, 15 + 6 * 15, 6).sum().item<double>(), 0);  // left shoulder (joint 16)
  EXPECT_EQ(g.narrow(0, 141, 66).sum().item<double>(), 0);         // derived positions
  EXPECT_FALSE(target.grad().defined() && target.grad().abs().sum().item<double>() > 0);
}

// Issue 15: the contact head's labels are the target's feet that stand still (slower than the
// speed), per frame from the displacements to both neighbours, at the frames' own rate.
TEST(Editor, ContactLabelsMarkTheFeetThatStandStill) {
  const int64_t frames = 16;
  const auto [stand, slide] = StandingAndSliding(frames);  // 0 and 0.5 m/s at 30 fps
  const auto still = ContactLabels(stand, 30, 0.15);
  ASSERT_EQ(still.sizes(), (std::vector<int64_t>{frames, 1, kContactJoints}));
  EXPECT_EQ(still.sum().item<double>(), static_cast<double>(frames * kContactJoints));
  EXPECT_EQ(ContactLabels(slide, 30, 0.15).sum().item<double>(), 0.0);
  // Read as 10-fps frames each step is 0.17 m/s; at 0.2 m/s the feet count as still.
  EXPECT_EQ(ContactLabels(slide, 10, 0.15).sum().item<double>(), 0.0);
  EXPECT_EQ(ContactLabels(slide, 10, 0.2).sum().item<double>(),
            static_cast<double>(frames * kContactJoints));
  // Standing for frames 0-7, then sliding: frame 7 averages a still pair and a sliding one
  // (0.25 m/s), so it moves; the last frame takes its one pair.
  auto both = stand.clone();  // the two differ in the pelvis velocity only
  both.narrow(0, 8, frames - 8).copy_(slide.narrow(0, 8, frames - 8));
  const auto mixed = ContactLabels(both, 30, 0.15).select(1, 0);  // [T, 4]
  for (int64_t f = 0; f < frames; ++f)
    for (int64_t q = 0; q < kContactJoints; ++q)
      EXPECT_EQ(mixed[f][q].item<float>(), f < 7 ? 1.0F : 0.0F) << "frame " << f << " joint " << q;
  EXPECT_EQ(ContactLabels(stand.narrow(0, 0, 1), 30, 0.15).sum().item<double>(), 0.0);
}

// The head's loss is the binary cross-entropy over real frames: ln 2 for logits 0, near 0 for
// confident right answers, and padded frames do not count; only a checkpoint with loss.contacts
// has the head.
TEST(Editor, TheContactHeadIsTrainedOnRealFramesOnly) {
  const auto labels = torch::ones({6, 2, kContactJoints});
  const auto none = torch::zeros({2, 6}, torch::kBool);
  EXPECT_NEAR(ContactLoss(torch::zeros({6, 2, kContactJoints}), labels, none).item<double>(),
              std::log(2.0), 1e-6);
  auto logits = torch::full({6, 2, kContactJoints}, 20.0);
  EXPECT_NEAR(ContactLoss(logits, labels, none).item<double>(), 0.0, 1e-6);
  auto padding = none.clone();
  padding[1].narrow(0, 3, 3).fill_(true);
  logits.select(1, 1).narrow(0, 3, 3).fill_(-20.0);  // wrong, but padded
  EXPECT_NEAR(ContactLoss(logits, labels, padding).item<double>(), 0.0, 1e-6);
  EXPECT_GT(ContactLoss(logits, labels, none).item<double>(), 1.0);

  const TinyTriplets data;
  const auto t = torch::full({3}, 10, torch::kInt64);
  const Condition c{data.texts, data.source, data.source_padding, {}, {}};
  for (const std::string variant : {"mdt", "tmed"}) {
    EditorOptions o = Tiny(variant, "none");
    EditorNet plain(o);
    plain->text_encoder()->Fit(data.texts);
    EXPECT_FALSE(plain->forward(data.target, t, data.target_padding, c).contacts.defined());
    o.contacts_weight = 1;
    EditorNet headed(o);
    headed->text_encoder()->Fit(data.texts);
    const auto p = headed->forward(data.target, t, data.target_padding, c);
    ASSERT_TRUE(p.contacts.defined()) << variant;
    EXPECT_EQ(p.contacts.sizes(), (std::vector<int64_t>{data.target.size(0), 3, kContactJoints}))
        << variant;
  }
  EXPECT_EQ(EditorOptions::FromJson({{"loss", {{"contacts", 0.5}}}}).ToJson()["loss"]["contacts"],
            0.5);
  EXPECT_THROW(EditorOptions::FromJson({{"loss", {{"contacts", -1}}}}), std::invalid_argument);
}

// The head's probabilities at the network's 10 fps, brought to 30 fps: linear in time, thresholded
// at 1/2, the last frame held past the end.
TEST(Editor, ContactsAtRateInterpolatesThenThresholds) {
  auto stands = torch::zeros({3, kContactJoints});
  stands[0][0] = 1;    // left ankle stands at 0 s, not at 0.1 s: it stands until 0.05 s
  stands[2][3] = 0.8;  // right toe stands from 0.2 s on, leaning in from 0.1 s
  const auto held = ContactsAtRate(stands, 10, 30, 9);
  ASSERT_EQ(held.size(), 9u * kContactJoints);
  const auto at = [&](int frame, int joint) {
    return held[static_cast<size_t>(frame * 4 + joint)];
  };
  EXPECT_EQ(at(0, 0), 1);
  EXPECT_EQ(at(1, 0), 1);  // 0.033 s: 2/3 of the way still
  EXPECT_EQ(at(2, 0), 0);  // 0.067 s: 1/3
  EXPECT_EQ(at(4, 3), 0);  // 0.133 s: 0.8/3
  EXPECT_EQ(at(5, 3), 1);  // 0.167 s: 0.8 * 2/3
  for (int frame = 6; frame < 9; ++frame) EXPECT_EQ(at(frame, 3), 1);  // past the end: held
  for (int frame = 0; frame < 9; ++frame) EXPECT_EQ(at(frame, 1) + at(frame, 2), 0);
  // At the network's own rate (fps 0) the frames map one to one.
  const auto same = ContactsAtRate(stands, 0, 30, 3);
  EXPECT_EQ(same[0], 1);
  EXPECT_EQ(same[4], 0);
  EXPECT_EQ(same[2 * 4 + 3], 1);
  EXPECT_THROW(ContactsAtRate(torch::zeros({3, 2}), 10, 30, 9), std::invalid_argument);
}

TEST(Editor, RegressionModePredictsTheNormalizedCurve) {
  EditorOptions o = Tiny("mdt", "regression");
  EXPECT_EQ(o.sim_outputs(), 1);
  // sigmoid(0) = 0.5 against S^N 0.5 and 1.0 on real frames with a curve; -1 = no curve.
  const auto prediction = torch::zeros({1, 3});
  const auto similarity = torch::tensor({{0.5f, 1.0f, -1.0f}});
  const auto classes = torch::tensor({{0, 2, -1}}, torch::kInt64);
  const auto out =
      SimilarityLoss(prediction, classes, similarity, torch::zeros({1, 3}, torch::kBool),
                     torch::tensor({0}).to(torch::kBool), o);
  EXPECT_NEAR(out.at("aux").item<double>(), (0.0 + 0.25) / 2, 1e-7);
  // K = 5 and K = 9 build their heads and default to equal class weights.
  for (int k : {5, 9}) {
    auto j = o.ToJson();
    j["aux"] = {{"mode", "classes"}, {"classes", k}};
    const EditorOptions ok = EditorOptions::FromJson(j);
    EXPECT_EQ(ok.sim_outputs(), k);
    EXPECT_EQ(ok.class_weights, std::vector<double>(static_cast<size_t>(k), 1.0));
  }
}

}  // namespace
}  // namespace motionpipe::mdt
