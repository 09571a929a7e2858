// LibTorch model code: the transformer layers against torch's own, the fast dropout, TEMOS's
// losses, overfitting, checkpoints, per-example noise.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "../../plugins/common/text_encoder.h"
#include "../../plugins/common/train_order.h"
#include "../../plugins/common/transformer.h"
#include "../../plugins/temos_sinc/sinc_data.h"
#include "../../plugins/temos_sinc/temos.h"
#include "motionpipe/features/temos135.h"
#include "motionpipe/formats/npz.h"

namespace motionpipe {
namespace {

// Copies torch's layer weights into ours (same arithmetic, different module layout).
void CopyAttention(torch::nn::MultiheadAttention& from, torch::nn::Module& to) {
  auto params = to.named_parameters();
  params["in_proj.weight"].copy_(from->in_proj_weight);
  params["in_proj.bias"].copy_(from->in_proj_bias);
  params["out_proj.weight"].copy_(from->out_proj->weight);
  params["out_proj.bias"].copy_(from->out_proj->bias);
}

TEST(Transformer, EncoderLayerComputesWhatTorchsDoes) {
  torch::manual_seed(3);
  torch::NoGradGuard no_grad;
  const int64_t dim = 32, heads = 4, ff = 64, length = 7, n = 3;
  torch::nn::TransformerEncoderLayer theirs(torch::nn::TransformerEncoderLayerOptions(dim, heads)
                                                .dim_feedforward(ff)
                                                .dropout(0.1)
                                                .activation(torch::kGELU));
  nn::EncoderLayer ours(nn::TransformerOptions{dim, heads, ff, 1, 0.1});
  CopyAttention(theirs->self_attn, *ours->named_children()["self_attn"]);
  auto p = ours->named_parameters();
  p["linear1.weight"].copy_(theirs->linear1->weight),
      p["linear1.bias"].copy_(theirs->linear1->bias);
  p["linear2.weight"].copy_(theirs->linear2->weight),
      p["linear2.bias"].copy_(theirs->linear2->bias);
  p["norm1.weight"].copy_(theirs->norm1->weight), p["norm1.bias"].copy_(theirs->norm1->bias);
  p["norm2.weight"].copy_(theirs->norm2->weight), p["norm2.bias"].copy_(theirs->norm2->bias);
  theirs->eval();
  ours->eval();
  const auto x = torch::randn({length, n, dim});
  auto padding = torch::zeros({n, length}, torch::kBool);
  padding[1].narrow(0, 4, 3).fill_(true);
  padding[2].narrow(0, 6, 1).fill_(true);
  const auto expected = theirs->forward(x, {}, padding);
  const auto got = ours->forward(x, padding);
  EXPECT_LT((expected - got).abs().max().item<double>(), 1e-5);
}

TEST(Transformer, OneTokenCrossAttentionComputesWhatTorchsDecoderDoes) {
  torch::manual_seed(4);
  torch::NoGradGuard no_grad;
  const int64_t dim = 32, heads = 4, ff = 64, length = 9, n = 2;
  torch::nn::TransformerDecoderLayer theirs(torch::nn::TransformerDecoderLayerOptions(dim, heads)
                                                .dim_feedforward(ff)
                                                .dropout(0.1)
                                                .activation(torch::kGELU));
  nn::OneTokenDecoderLayer ours(nn::TransformerOptions{dim, heads, ff, 1, 0.1});
  CopyAttention(theirs->self_attn, *ours->named_children()["self_attn"]);
  auto p = ours->named_parameters();
  // Cross-attention: only the value third of torch's input projection matters with one key.
  p["cross_value.weight"].copy_(theirs->multihead_attn->in_proj_weight.narrow(0, 2 * dim, dim));
  p["cross_value.bias"].copy_(theirs->multihead_attn->in_proj_bias.narrow(0, 2 * dim, dim));
  p["cross_out_proj.weight"].copy_(theirs->multihead_attn->out_proj->weight);
  p["cross_out_proj.bias"].copy_(theirs->multihead_attn->out_proj->bias);
  p["linear1.weight"].copy_(theirs->linear1->weight),
      p["linear1.bias"].copy_(theirs->linear1->bias);
  p["linear2.weight"].copy_(theirs->linear2->weight),
      p["linear2.bias"].copy_(theirs->linear2->bias);
  for (const char* norm : {"norm1", "norm2", "norm3"}) {
    auto theirs_norm = theirs->named_parameters();
    p[std::string(norm) + ".weight"].copy_(theirs_norm[std::string(norm) + ".weight"]);
    p[std::string(norm) + ".bias"].copy_(theirs_norm[std::string(norm) + ".bias"]);
  }
  theirs->eval();
  ours->eval();
  const auto x = torch::randn({length, n, dim});
  const auto z = torch::randn({n, dim});
  auto padding = torch::zeros({n, length}, torch::kBool);
  padding[0].narrow(0, 5, 4).fill_(true);
  const auto expected = theirs->forward(x, z.unsqueeze(0), {}, {}, padding);
  const auto got = ours->forward(x, z, padding);
  EXPECT_LT((expected - got).abs().max().item<double>(), 1e-5);
}

TEST(Transformer, TrainingDropoutRepeatsUnderASeedAndVariesAcrossSeeds) {
  torch::manual_seed(5);
  const int64_t dim = 16, heads = 4, length = 5, n = 3;
  nn::OneTokenDecoderLayer layer(nn::TransformerOptions{dim, heads, 32, 1, 0.5});
  layer->train();
  const auto x = torch::randn({length, n, dim});
  const auto z = torch::randn({n, dim});
  const auto padding = torch::zeros({n, length}, torch::kBool);
  // Equal seeds: our forward draws the self-attention masks, then the cross weights; a second run
  // under the same seed must give the same output (masks repeat), and differ under another seed.
  torch::manual_seed(11);
  const auto a = layer->forward(x, z, padding);
  torch::manual_seed(11);
  const auto b = layer->forward(x, z, padding);
  torch::manual_seed(12);
  const auto c = layer->forward(x, z, padding);
  EXPECT_TRUE(torch::equal(a, b));
  EXPECT_FALSE(torch::equal(a, c));
  EXPECT_TRUE(torch::isfinite(a).all().item<bool>());
}

TEST(Transformer, DropoutMaskHasTheRightRateAndScale) {
  torch::manual_seed(1);
  const auto mask = nn::DropoutMask({1000, 1001}, 0.1);
  const double zeros = mask.eq(0).to(torch::kFloat64).mean().item<double>();
  EXPECT_NEAR(zeros, 0.1, 0.002);
  EXPECT_NEAR(mask.to(torch::kFloat64).mean().item<double>(), 1.0, 0.003);
  EXPECT_NEAR(mask.max().item<double>(), 1.0 / 0.9, 1e-6);
  torch::manual_seed(1);
  EXPECT_TRUE(torch::equal(mask, nn::DropoutMask({1000, 1001}, 0.1)));
  const auto x = torch::randn({4, 5});
  EXPECT_TRUE(torch::equal(nn::Dropout(x, 0.1, false), x));
  EXPECT_TRUE(torch::equal(nn::Dropout(x, 0.0, true), x));
}

// `options` (optional) adds or overrides TemosOptions keys.
temos::Temos TinyTemos(double dropout, const nlohmann::json& options = nlohmann::json::object()) {
  nlohmann::json config = {
      {"latent", 32},       {"layers", 1},
      {"heads", 2},         {"ff", 64},
      {"dropout", dropout}, {"text_encoder", {{"layers", 1}, {"vocab", 60}, {"ff", 64}}}};
  config.update(options);
  temos::Temos net(temos::TemosOptions::FromJson(config));
  net->text_encoder()->Fit(
      {"walk forward", "wave the right hand", "jump in place", "sit down slowly", "turn left"});
  return net;
}

struct TinyBatch {
  std::vector<std::vector<std::string>> texts = {
      {"walk forward"}, {"wave the right hand"}, {"jump in place"}, {"sit down slowly"}};
  torch::Tensor features, padding;
  TinyBatch() {
    torch::manual_seed(9);
    const int64_t frames = 20;
    padding = torch::zeros({4, frames}, torch::kBool);
    padding[1].narrow(0, 15, 5).fill_(true);
    padding[3].narrow(0, 12, 8).fill_(true);
    // Smooth curves per example (so the decoder can fit them), zero on padded frames.
    const auto t = torch::linspace(0, 1, frames).view({frames, 1, 1});
    const auto phase = torch::randn({1, 4, temos::kFeatureDim});
    features = torch::sin(6.0 * t + phase).masked_fill(padding.t().unsqueeze(2), 0.0);
  }
};

TEST(Temos, MaskedLossIgnoresPaddingAndWeighsExamplesEqually) {
  const auto target = torch::zeros({4, 2, 3});
  auto prediction = torch::zeros({4, 2, 3});
  auto padding = torch::zeros({2, 4}, torch::kBool);
  padding[1].narrow(0, 1, 3).fill_(true);                // example 1 has one frame
  prediction.select(1, 1).narrow(0, 1, 3).fill_(100.0);  // garbage on its padded frames: ignored
  prediction[1][0].fill_(0.5);  // example 0: one of 4 frames off by 0.5 -> smooth-L1 0.125
  // example 0's mean: 0.125 / 4; example 1's: 0 -> batch mean 0.015625
  EXPECT_NEAR(temos::MaskedSmoothL1(prediction, target, padding).item<double>(), 0.125 / 4 / 2,
              1e-7);
}

// Issue 15: the velocity term sees the within-motion change alone (a constant posture offset costs
// nothing, a motion held still costs its whole movement), ignores padded frames, and does not
// depend on the features' scale.
TEST(Temos, VelocityLossSeesMovementNotPostureAndIgnoresPadding) {
  const int64_t frames = 8;
  const auto t = torch::arange(frames, torch::kFloat32).view({frames, 1, 1});
  const auto target = torch::sin(t * torch::tensor({0.7f, 1.1f, 0.4f}).view({1, 1, 3}))
                          .expand({frames, 2, 3})
                          .contiguous();
  auto padding = torch::zeros({2, frames}, torch::kBool);
  padding[1].narrow(0, 5, 3).fill_(true);  // example 1 has 5 frames
  using temos::MaskedVelocitySmoothL1;
  EXPECT_NEAR(MaskedVelocitySmoothL1(target + 3.0, target, padding).item<double>(), 0.0, 1e-7);
  const auto still = target.mean(0, true).expand_as(target).contiguous();
  const double held = MaskedVelocitySmoothL1(still, target, padding).item<double>();
  EXPECT_GT(held, 0.1);
  auto garbage = still.clone();
  garbage.select(1, 1).narrow(0, 5, 3).fill_(100.0);  // on example 1's padded frames: ignored
  EXPECT_NEAR(MaskedVelocitySmoothL1(garbage, target, padding).item<double>(), held, 1e-6);
  EXPECT_NEAR(MaskedVelocitySmoothL1(10 * still, 10 * target, padding).item<double>(), held, 1e-5);
  // One frame: no difference to compare.
  EXPECT_EQ(
      MaskedVelocitySmoothL1(still.narrow(0, 0, 1), target.narrow(0, 0, 1), padding.narrow(1, 0, 1))
          .item<double>(),
      0.0);
}

TEST(Temos, VelocityWeightAddsTheVelocityTermsToTheLoss) {
  const TinyBatch batch;
  const auto seeds = torch::tensor({1, 2, 3, 4}, torch::kInt64);
  torch::manual_seed(4);
  auto plain = TinyTemos(0.0);
  torch::manual_seed(4);
  auto net = TinyTemos(0.0, {{"velocity_weight", 0.5}, {"text_reconstruction", 0.25}});
  const auto a = plain->Losses(batch.texts, batch.features, batch.padding, seeds);
  const auto b = net->Losses(batch.texts, batch.features, batch.padding, seeds);
  EXPECT_EQ(a.count("velocity_motion"), 0u);  // the reference's losses alone by default
  EXPECT_GT(b.at("velocity_motion").item<double>(), 0.01);
  const auto expected = a.at("loss") - 0.75 * a.at("recon_text") +
                        0.5 * (0.25 * b.at("velocity_text") + b.at("velocity_motion"));
  EXPECT_NEAR(b.at("loss").item<double>(), expected.item<double>(), 1e-5);
  EXPECT_EQ(net->options().ToJson().at("velocity_weight").get<double>(), 0.5);
  EXPECT_THROW(temos::TemosOptions::FromJson({{"velocity_weight", -1}}), std::invalid_argument);
}

// data.limit: the first examples of the split in the table's order, the spans a generate stage with
// the same split, kind and limit reads (issue 15's fitting diagnostic).
TEST(SincData, LimitKeepsTheSplitsFirstExamplesInTheTablesOrder) {
  auto table = std::make_shared<sinc::SpanTable>();
  const std::vector<std::array<std::string, 3>> spans = {{"train", "walk", "wave"},
                                                         {"test", "jump", "clap"},
                                                         {"train", "sit", ""},
                                                         {"train", "kick", "bow"},
                                                         {"train", "run", "nod"}};
  for (size_t i = 0; i < spans.size(); ++i) {
    table->Add("s" + std::to_string(i), spans[i][0], "made", Motion::Rest(20 + 5 * i, 30, 0.9),
               spans[i][1], spans[i][2]);
  }
  temos::SincDataOptions options;
  options.spans = "made.npz";
  options.singles = false;
  options.synthetic_p = 0;
  options.augment_texts = false;
  auto actions = [&](const temos::SincDataset& data) {
    std::vector<std::string> out;
    for (int64_t i = 0; i < data.size(); ++i) out.push_back(data.Make(i, 1).actions.at(0));
    return out;
  };
  EXPECT_EQ(actions(temos::SincDataset(table, options)),
            (std::vector<std::string>{"walk", "kick", "run"}));
  options.limit = 2;
  EXPECT_EQ(actions(temos::SincDataset(table, options)),
            (std::vector<std::string>{"walk", "kick"}));
  options.limit = 9;  // more than there are: all of them
  EXPECT_EQ(temos::SincDataset(table, options).size(), 3);
  plugin::DataContext context;
  context.config = {{"spans", "made.npz"}, {"limit", -1}};
  EXPECT_THROW(temos::SincDataOptions::FromContext(context), std::invalid_argument);
}

// Issue 15: SINC at its own rate (the model's `fps`) trains on every k-th frame of its spans, with
// the velocities over k frames in the examples and in the statistics; max_frames counts the
// network's frames; a rate that does not divide the data's is refused, naming the spans file.
TEST(SincData, FpsKeepsEveryKthFrameWithItsVelocitiesAndStatistics) {
  auto table = std::make_shared<sinc::SpanTable>();
  Motion walk = Motion::Rest(31, 30, 0.9);
  for (int64_t f = 0; f < 31; ++f)
    walk.SetTranslation(f, {0.03 * static_cast<double>(f), 0.01 * static_cast<double>(f), 0.9});
  table->Add("s0", "train", "made", walk, "walk", "");
  temos::SincDataOptions options;
  options.spans = "made.npz";
  options.synthetic_p = 0;
  options.augment_texts = false;
  temos::SincDataset full_rate(table, options);
  const temos::Example full = full_rate.Make(0, 1);
  ASSERT_EQ(full.frames, 31);
  options.fps = 10;
  temos::SincDataset tenth(table, options);
  const temos::Example ex = tenth.Make(0, 1);
  ASSERT_EQ(ex.frames, 11);
  std::vector<float> expected = full.features;
  ASSERT_EQ(EveryKthTemos135(expected.data(), 31, 3, expected.data()), 11);
  expected.resize(static_cast<size_t>(11 * kTemosFeatureDim));
  EXPECT_EQ(ex.features, expected);
  // A network frame spans 3 of the data's: three times the displacement, in the examples and in
  // the statistics (frame 0 has none: 30 of 31 frames move by v, 10 of 11 by 3 v).
  const auto speed = [](const float* row) { return std::hypot(row[1], row[2]); };
  const double v = speed(full.features.data() + kTemosFeatureDim);
  EXPECT_NEAR(v, std::hypot(0.03, 0.01), 1e-6);
  EXPECT_NEAR(speed(ex.features.data() + 5 * kTemosFeatureDim), 3 * v, 1e-6);
  const auto mean_speed = [&](const temos::SincDataset& data) {
    const torch::Tensor mean = data.ComputeStats().first;
    return std::hypot(mean[1].item<double>(), mean[2].item<double>());
  };
  EXPECT_NEAR(mean_speed(full_rate), v * 30 / 31, 1e-6);
  EXPECT_NEAR(mean_speed(tenth), 3 * v * 10 / 11, 1e-6);
  options.max_frames = 5;
  EXPECT_EQ(temos::SincDataset(table, options).Make(0, 1).frames, 5);
  EXPECT_EQ(temos::FramesPerNetworkFrame(30, 0), 1);
  EXPECT_EQ(temos::FramesPerNetworkFrame(30, 30), 1);
  EXPECT_EQ(temos::FramesPerNetworkFrame(30, 15), 2);
  EXPECT_THROW(temos::FramesPerNetworkFrame(30, 60), std::invalid_argument);
  options.fps = 7;
  try {
    temos::SincDataset refused(table, options);
    ADD_FAILURE() << "a rate that does not divide 30 fps was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("made.npz"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("not a whole multiple"), std::string::npos) << e.what();
  }
}

TEST(Temos, KlOfIdenticalGaussiansIsZeroAndMatchesTheClosedForm) {
  const auto mu = torch::tensor({{0.5f, -1.0f}});
  const auto logvar = torch::tensor({{0.2f, -0.3f}});
  EXPECT_NEAR(temos::KlDivergence(mu, logvar, mu, logvar).item<double>(), 0.0, 1e-7);
  const auto zeros = torch::zeros({1, 2});
  // KL(N(mu, s^2) || N(0, 1)) = 0.5 * sum(s^2 + mu^2 - 1 - log s^2)
  // ... averaged over the dimensions, as the reference's kl_divergence(q, p).mean().
  const double expected =
      0.5 * ((std::exp(0.2) + 0.25 - 1 - 0.2) + (std::exp(-0.3) + 1.0 - 1 + 0.3)) / 2;
  EXPECT_NEAR(temos::KlDivergence(mu, logvar, zeros, zeros).item<double>(), expected, 1e-6);
}

// Issue 15: the KL terms were summed over the latent dimensions, so the effective KL weight was
// `latent` times TEMOS/TMR/SINC's (their div.mean() averages over every element).
TEST(Temos, KlIsTheMeanOverEveryElementLikeTheReference) {
  torch::manual_seed(6);
  const auto mu_q = torch::randn({5, 64}), logvar_q = 0.3 * torch::randn({5, 64});
  const auto mu_p = torch::randn({5, 64}), logvar_p = 0.3 * torch::randn({5, 64});
  // torch.distributions.kl_divergence(Normal(mu_q, s_q), Normal(mu_p, s_p)) element by element
  const auto var_ratio = torch::exp(logvar_q - logvar_p);
  const auto t1 = (mu_q - mu_p).pow(2) / torch::exp(logvar_p);
  const auto elementwise = 0.5 * (var_ratio + t1 - 1 - (logvar_q - logvar_p));
  EXPECT_NEAR(temos::KlDivergence(mu_q, logvar_q, mu_p, logvar_p).item<double>(),
              elementwise.mean().item<double>(), 1e-5);
  // Doubling the latent size with copies of the same dimensions leaves the KL unchanged.
  EXPECT_NEAR(temos::KlDivergence(torch::cat({mu_q, mu_q}, 1), torch::cat({logvar_q, logvar_q}, 1),
                                  torch::cat({mu_p, mu_p}, 1), torch::cat({logvar_p, logvar_p}, 1))
                  .item<double>(),
              elementwise.mean().item<double>(), 1e-5);
}

// Issue 15: a 135-d feature column constant over the training motions had std 0, and the demo's
// TMR turned a copy with 0.1 degree of joint noise into chance retrieval. Such a column keeps std
// 1; the others get their own.
TEST(Temos, ConstantFeatureColumnsKeepUnitScale) {
  using temos::StatsFromSums;
  // Three columns over 4 frames: values {1, 1, 1, 1}, {0, 2, 0, 2}, {0.5, 0.5, 0.5, 0.5}.
  const std::vector<double> sum = {4, 4, 2}, squares = {4, 8, 1};
  const auto [mean, stddev] = StatsFromSums(sum, squares, 4);
  EXPECT_NEAR(mean[0].item<double>(), 1.0, 1e-6);
  EXPECT_NEAR(mean[1].item<double>(), 1.0, 1e-6);
  EXPECT_NEAR(stddev[0].item<double>(), 1.0, 1e-6);  // constant: unit scale, not 0
  EXPECT_NEAR(stddev[1].item<double>(), 1.0, 1e-6);  // population std of {0, 2, 0, 2}
  EXPECT_NEAR(stddev[2].item<double>(), 1.0, 1e-6);
  const auto [m2, s2] = StatsFromSums({0.0}, {0.04}, 1);  // one frame: variance 0.04 - 0 = 0.04
  EXPECT_NEAR(s2[0].item<double>(), 0.2, 1e-6);
}

// The retrieval a training run logs beside its losses (issue 15: time to a TMR's quality): texts
// whose own motion is strictly the nearest by cosine, in percent.
TEST(Temos, BatchRetrievalR1CountsTextsWhoseOwnMotionIsStrictlyNearest) {
  // Text 0 and 3 are nearest their own motions; text 1 is nearer motion 0 than its own motion 1;
  // text 2's own motion 2 ties with motion 1 (a tie is a miss, as the evaluation's averaged ranks).
  const auto text = torch::tensor({{1.f, 0.f}, {1.f, 0.1f}, {0.f, 1.f}, {-1.f, 0.f}});
  const auto motion = torch::tensor({{2.f, 0.f}, {0.f, 3.f}, {0.f, 1.f}, {-0.5f, 0.2f}});
  const auto r1 = temos::BatchRetrievalR1(text, motion);
  EXPECT_EQ(r1.scalar_type(), torch::kFloat);
  EXPECT_DOUBLE_EQ(r1.item<double>(), 50.0);
  // Cosine: the scale of either side does not matter; bf16 inputs give the same answer here.
  EXPECT_DOUBLE_EQ(temos::BatchRetrievalR1(7 * text, 0.1 * motion).item<double>(), 50.0);
  EXPECT_DOUBLE_EQ(temos::BatchRetrievalR1(text.to(torch::kBFloat16), motion.to(torch::kBFloat16))
                       .item<double>(),
                   50.0);
  // Each text's own motion made its nearest: 100; the motions reversed: only the middle pair.
  EXPECT_DOUBLE_EQ(temos::BatchRetrievalR1(text, text).item<double>(), 100.0);
  const auto three = torch::tensor({{1.f, 0.f}, {0.6f, 0.8f}, {0.f, 1.f}});
  EXPECT_NEAR(temos::BatchRetrievalR1(three, three.flip(0)).item<double>(), 100.0 / 3, 1e-4);
}

// The train stage's stream (plugins/common/train_order.h): two ranks' shares interleave into the
// one-rank batch with the same seeds, an epoch visits every example once, and the schedule warms
// up linearly and ends at min_lr.
TEST(TrainOrder, RanksShareTheGlobalBatchAndAnEpochVisitsEveryExampleOnce) {
  nn::EpochOrder one(10, 4, 7), rank0(10, 4, 7), rank1(10, 4, 7);
  std::vector<int64_t> seen;
  for (int64_t step = 0; step < 2; ++step) {  // 10 / 4 = 2 batches an epoch
    const auto all = one.Indices(step), a = rank0.Indices(step, 0, 2),
               b = rank1.Indices(step, 1, 2);
    ASSERT_EQ(all.size(), 4u);
    EXPECT_EQ(std::vector<int64_t>({a[0], b[0], a[1], b[1]}), all);
    const auto seeds = one.ExampleSeeds(step), s0 = one.ExampleSeeds(step, 0, 2);
    EXPECT_EQ(s0, std::vector<int64_t>({seeds[0], seeds[2]}));
    for (const int64_t seed : seeds) EXPECT_GE(seed, 0);
    seen.insert(seen.end(), all.begin(), all.end());
  }
  std::sort(seen.begin(), seen.end());
  EXPECT_EQ(std::adjacent_find(seen.begin(), seen.end()), seen.end()) << "an example twice";
  EXPECT_NE(one.Indices(2), one.Indices(0)) << "the next epoch is shuffled again";
  EXPECT_NE(one.BatchSeed(0), one.BatchSeed(1));
  const nn::LearningRateSchedule cosine{1e-3, 1e-5, 10, 110, true};
  EXPECT_DOUBLE_EQ(cosine.At(0), 1e-4);
  EXPECT_DOUBLE_EQ(cosine.At(9), 1e-3);
  EXPECT_NEAR(cosine.At(60), 0.5 * (1e-3 + 1e-5), 1e-12);
  EXPECT_DOUBLE_EQ(cosine.At(110), 1e-5);
  EXPECT_DOUBLE_EQ((nn::LearningRateSchedule{1e-3, 0, 10, 110, false}.At(80)), 1e-3);
}

TEST(Temos, NearDuplicatesAreExamplesWhoseWordCountsHaveCosineAboveTheThreshold) {
  // Words lower-cased, an example's texts joined: 0 and 3 have the same words (cosine 1); 0 and 1
  // share two of three (cosine 2 / sqrt(6) = 0.816); "jump" and "jump, jump" count the same word.
  const std::vector<std::vector<std::string>> texts = {
      {"walk forward"}, {"Walk forward slowly"}, {"jump"}, {"walk", "forward"}, {"jump, jump"}};
  const auto dup = temos::NearDuplicates(texts, 0.6);
  ASSERT_EQ(dup.sizes(), (std::vector<int64_t>{5, 5}));
  const auto at = [&](int64_t i, int64_t j) { return dup[i][j].item<bool>(); };
  for (int64_t i = 0; i < 5; ++i) EXPECT_FALSE(at(i, i)) << "the diagonal is never masked";
  EXPECT_TRUE(at(0, 1) && at(1, 0));
  EXPECT_TRUE(at(0, 3) && at(1, 3));
  EXPECT_TRUE(at(2, 4));
  EXPECT_FALSE(at(0, 2) || at(1, 4) || at(3, 2));
  const auto strict = temos::NearDuplicates(texts, 0.9);  // 0.816 is not above 0.9
  EXPECT_FALSE(strict[0][1].item<bool>());
  EXPECT_TRUE(strict[0][3].item<bool>());
}

TEST(Temos, LossesLogTheBatchRetrievalOfTheEncodersMeansWithoutGradient) {
  auto net = TinyTemos(0.0, {{"contrastive", 0.1}});
  net->eval();
  const TinyBatch batch;
  const auto seeds = torch::arange(4, torch::kInt64);
  const auto losses = net->Losses(batch.texts, batch.features, batch.padding, seeds);
  ASSERT_EQ(losses.count("retrieval_r1"), 1u);
  EXPECT_FALSE(losses.at("retrieval_r1").requires_grad());
  torch::NoGradGuard no_grad;
  const auto expected =
      temos::BatchRetrievalR1(net->EncodeText(batch.texts, false).mu,
                              net->EncodeMotion(batch.features, batch.padding, false).mu);
  EXPECT_DOUBLE_EQ(losses.at("retrieval_r1").item<double>(), expected.item<double>());
  // Not part of the loss: the loss is the weighted sum of the other terms.
  const auto& l = losses;
  const auto kl =
      l.at("kl_text_motion") + l.at("kl_motion_text") + l.at("kl_text") + l.at("kl_motion");
  EXPECT_NEAR(l.at("loss").item<double>(),
              (l.at("recon_text") + l.at("recon_motion") + 1e-5 * kl + 1e-5 * l.at("latent") +
               0.1 * l.at("contrastive"))
                  .item<double>(),
              1e-6);
}

TEST(Temos, OverfitsASmallBatch) {
  torch::manual_seed(2);
  auto net = TinyTemos(0.0);
  const TinyBatch batch;
  torch::optim::AdamW optimizer(net->parameters(), torch::optim::AdamWOptions(2e-3));
  net->train();
  double first = 0, last = 0;
  for (int step = 0; step < 150; ++step) {
    auto losses = net->Losses(batch.texts, batch.features, batch.padding);
    optimizer.zero_grad();
    losses.at("loss").backward();
    optimizer.step();
    if (step == 0) first = losses.at("loss").item<double>();
    last = losses.at("loss").item<double>();
  }
  EXPECT_LT(last, 0.25 * first) << "first " << first << " last " << last;
}

TEST(Temos, TextReconstructionWeightScalesOnlyTheTextBranchsReconstruction) {
  const TinyBatch batch;
  const auto seeds = torch::tensor({1, 2, 3, 4}, torch::kInt64);
  for (const double weight : {1.0, 0.0, 0.5}) {
    torch::manual_seed(4);
    auto net = TinyTemos(0.0, {{"text_reconstruction", weight}});
    const auto l = net->Losses(batch.texts, batch.features, batch.padding, seeds);
    const auto kl =
        l.at("kl_text_motion") + l.at("kl_motion_text") + l.at("kl_text") + l.at("kl_motion");
    const auto expected =
        weight * l.at("recon_text") + l.at("recon_motion") + 1e-5 * kl + 1e-5 * l.at("latent");
    EXPECT_NEAR(l.at("loss").item<double>(), expected.item<double>(), 1e-6) << weight;
    EXPECT_GT(l.at("recon_text").item<double>(), 0.01);  // reported whatever its weight
  }
  EXPECT_THROW(temos::TemosOptions::FromJson({{"text_reconstruction", -1}}), std::invalid_argument);
}

TEST(Temos, WithoutLatentNoiseTheLossesDoNotDependOnTheNoiseSeeds) {
  const TinyBatch batch;
  for (const double noise : {0.0, 1.0}) {
    torch::manual_seed(5);
    auto net = TinyTemos(0.0, {{"latent_noise", noise}});
    const auto a = net->Losses(batch.texts, batch.features, batch.padding,
                               torch::tensor({1, 2, 3, 4}, torch::kInt64));
    const auto b = net->Losses(batch.texts, batch.features, batch.padding,
                               torch::tensor({5, 6, 7, 8}, torch::kInt64));
    EXPECT_EQ(torch::equal(a.at("recon_motion"), b.at("recon_motion")), noise == 0) << noise;
    EXPECT_EQ(torch::equal(a.at("recon_text"), b.at("recon_text")), noise == 0) << noise;
  }
}

TEST(Temos, FilmDecoderStartsAsTemossDecoder) {
  // The same draws for every shared weight; the FiLM layer is zero-initialised, so the decoders
  // agree.
  const auto z = torch::randn({3, 32});
  const auto padding = torch::zeros({3, 10}, torch::kBool);
  torch::manual_seed(6);
  auto memory = TinyTemos(0.0, {{"layers", 2}});
  torch::manual_seed(6);
  auto film = TinyTemos(0.0, {{"layers", 2}, {"decoder", "film"}});
  EXPECT_TRUE(torch::allclose(memory->Decode(z, padding), film->Decode(z, padding), 1e-6, 1e-6));
  EXPECT_EQ(film->options().ToJson().at("decoder"), "film");
  EXPECT_EQ(memory->options().ToJson().at("decoder"), "memory");
  EXPECT_THROW(temos::TemosOptions::FromJson({{"decoder", "films"}}), std::invalid_argument);
}

TEST(Transformer, OneTokenDecoderModulationScalesAndShiftsEachLayersQueries) {
  torch::manual_seed(8);
  nn::OneTokenDecoder decoder(nn::TransformerOptions{16, 2, 32, 2, 0.0});
  const auto x = torch::randn({6, 3, 16}), memory = torch::randn({3, 16});
  const auto padding = torch::zeros({3, 6}, torch::kBool);
  // Scale -1 before the first layer: every frame's query becomes the shift, so every frame decodes
  // alike; an identity modulation (all zeros) changes nothing.
  auto modulation = torch::zeros({2, 3, 32});
  EXPECT_TRUE(torch::allclose(decoder->forward(x, memory, padding, modulation),
                              decoder->forward(x, memory, padding), 1e-6, 1e-6));
  modulation[0].narrow(1, 0, 16).fill_(-1.0);
  modulation[0].narrow(1, 16, 16).copy_(torch::randn({3, 16}));
  const auto y = decoder->forward(x, memory, padding, modulation);
  EXPECT_TRUE(torch::allclose(y, y[0].unsqueeze(0).expand_as(y), 1e-5, 1e-5));
  EXPECT_FALSE(torch::allclose(y, decoder->forward(x, memory, padding), 1e-3, 1e-3));
  EXPECT_THROW(decoder->forward(x, memory, padding, torch::zeros({1, 3, 32})),
               std::invalid_argument);
}

TEST(Temos, SavedAndLoadedModelGivesIdenticalOutputs) {
  torch::manual_seed(3);
  auto net = TinyTemos(0.1);
  net->eval();
  const TinyBatch batch;
  const std::string dir = ::testing::TempDir() + "/temos_ckpt";
  std::filesystem::create_directories(dir);
  torch::serialize::OutputArchive out;
  net->save(out);
  out.save_to(dir + "/model.pt");
  net->text_encoder()->SaveExtras(dir);
  torch::manual_seed(99);  // different initial weights
  auto loaded = TinyTemos(0.1);
  loaded->text_encoder()->LoadExtras(dir);
  torch::serialize::InputArchive in;
  in.load_from(dir + "/model.pt");
  loaded->load(in);
  loaded->eval();
  torch::NoGradGuard no_grad;
  const auto a = net->EncodeText(batch.texts, false);
  const auto b = loaded->EncodeText(batch.texts, false);
  EXPECT_TRUE(torch::equal(a.mu, b.mu));
  EXPECT_TRUE(torch::equal(net->Decode(a.mu, batch.padding), loaded->Decode(b.mu, batch.padding)));
  EXPECT_TRUE(torch::equal(net->EncodeMotion(batch.features, batch.padding, false).mu,
                           loaded->EncodeMotion(batch.features, batch.padding, false).mu));
}

TEST(Temos, ExampleNoiseDependsOnlyOnTheExamplesSeed) {
  const auto all = temos::ExampleNoise(torch::tensor({11, 12, 13, 14}, torch::kInt64), 2, 8);
  const auto odd = temos::ExampleNoise(torch::tensor({12, 14}, torch::kInt64), 2, 8);
  ASSERT_EQ(all.sizes(), (std::vector<int64_t>{2, 4, 8}));
  EXPECT_TRUE(torch::equal(all.select(1, 1), odd.select(1, 0)));
  EXPECT_TRUE(torch::equal(all.select(1, 3), odd.select(1, 1)));
  EXPECT_FALSE(torch::equal(all.select(1, 0), all.select(1, 1)));
}

TEST(Temos, SplitBatchGradientsAverageToTheUnionBatchGradient) {
  // The train stage averages the ranks' gradients; with per-example losses and per-example noise
  // that is the union batch's gradient (dropout off, where masks would differ by construction).
  torch::manual_seed(6);
  auto net = TinyTemos(0.0);
  net->train();
  const TinyBatch batch;
  const auto seeds = torch::tensor({101, 102, 103, 104}, torch::kInt64);
  const auto gradients = [&](const std::vector<int64_t>& rows) {
    const auto index = torch::tensor(rows, torch::kInt64);
    std::vector<std::vector<std::string>> texts;
    for (int64_t r : rows) texts.push_back(batch.texts[static_cast<size_t>(r)]);
    net->zero_grad();
    net->Losses(texts, batch.features.index_select(1, index), batch.padding.index_select(0, index),
                seeds.index_select(0, index))
        .at("loss")
        .backward();
    std::vector<torch::Tensor> g;
    for (const auto& p : net->parameters())
      g.push_back(p.grad().defined() ? p.grad().clone() : torch::zeros_like(p));
    return g;
  };
  const auto whole = gradients({0, 1, 2, 3});
  const auto even = gradients({0, 2});
  const auto odd = gradients({1, 3});
  double worst = 0;
  const auto names = net->named_parameters().keys();
  for (size_t k = 0; k < whole.size(); ++k) {
    const double error = ((even[k] + odd[k]) / 2 - whole[k]).abs().max().item<double>();
    EXPECT_LT(error, 1e-5) << names[k];
    worst = std::max(worst, error);
  }
  EXPECT_LT(worst, 1e-5);
}

}  // namespace
}  // namespace motionpipe

namespace motionpipe {
namespace {

TEST(TextEncoder, PrecomputedTableGivesItsEmbeddingsAndNamesUnknownTexts) {
  const std::string path = ::testing::TempDir() + "/clip_features.npz";
  Npz npz;
  npz.Add("texts", NpyArray::Strings({2}, {"walk forward", "wave the right hand"}));
  npz.Add("embeddings", NpyArray::Float32({2, 3}, {1, 0, 0, 0, 1, 0}));
  ASSERT_TRUE(WriteNpz(path, npz).ok());
  nn::TextEncoder encoder(nn::TextEncoderOptions::FromJson(
      {{"kind", "precomputed"}, {"table", path}, {"dim", 8}, {"heads", 2}, {"layers", 1}}));
  encoder->Fit({});
  encoder->eval();
  torch::NoGradGuard no_grad;
  const auto a = encoder->forward({"walk forward", "wave the right hand", "walk forward"});
  ASSERT_EQ(a.tokens.sizes(), (std::vector<int64_t>{1, 3, 8}));
  // The same text, the same features: to rounding, as a BLAS need not multiply every row of a batch
  // by the same instruction sequence (on a 2.3-GHz Intel Xeon, OpenBLAS gave rows 0 and 2 a
  // different last bit: 2.4e-7).
  EXPECT_LT((a.tokens.select(1, 0) - a.tokens.select(1, 2)).abs().max().item<double>(), 1e-6);
  EXPECT_FALSE(torch::equal(a.tokens.select(1, 0), a.tokens.select(1, 1)));
  try {
    encoder->forward({"jump"});
    FAIL() << "an unknown text must be refused";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("no embedding for 'jump'"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
  nn::TextEncoder missing(
      nn::TextEncoderOptions::FromJson({{"kind", "precomputed"}, {"dim", 8}, {"heads", 2}}));
  EXPECT_THROW(missing->Fit({}), std::invalid_argument);
}

// Issue 15: token embeddings started N(0, 1) and were multiplied by sqrt(d), so the first layer's
// softmax was saturated (hard attention) and its query/key projections got almost no gradient.
TEST(TextEncoder, FirstLayerAttentionIsSoftAndItsQueriesAndKeysLearn) {
  torch::manual_seed(7);
  const int64_t dim = 128;
  nn::TextEncoder encoder(nn::TextEncoderOptions::FromJson(
      {{"dim", dim}, {"heads", 4}, {"layers", 1}, {"dropout", 0.0}, {"vocab", 200}}));
  const std::vector<std::string> texts = {"walk forward slowly",     "wave the right hand",
                                          "jump in place twice",     "turn around to the left",
                                          "kick with the right leg", "sit down on the floor"};
  encoder->Fit(texts);
  // The embedded tokens (what forward() scales by sqrt(d)) have a spread of about 1, like the
  // positions.
  const auto ids = encoder->TokenIds(texts);
  const auto embedded =
      encoder->named_parameters()["embed.weight"].index_select(0, ids.view({-1})) *
      std::sqrt(static_cast<double>(dim));
  EXPECT_LT(embedded.std().item<double>(), 1.5);
  EXPECT_GT(embedded.std().item<double>(), 0.5);
  // The query and key rows of the first attention's input projection receive a gradient of the same
  // order as the value rows (a saturated softmax passes them next to nothing).
  const auto out = encoder->forward(texts);
  (out.tokens * torch::randn_like(out.tokens)).sum().backward();
  const auto grad = encoder->named_parameters()["encoder.layers.0.self_attn.in_proj.weight"].grad();
  ASSERT_TRUE(grad.defined());
  const double query_key = grad.narrow(0, 0, 2 * dim).norm().item<double>() / std::sqrt(2.0);
  const double value = grad.narrow(0, 2 * dim, dim).norm().item<double>();
  EXPECT_GT(query_key, 0.05 * value)
      << "query/key gradient " << query_key << " value gradient " << value;
}

// A TMR-style checkpoint's text encoder, copied into another model's (the MDT's, SINC's): the same
// features for the same texts, its tokenizer, frozen or not, and a clear error when the settings
// differ.
TEST(TextEncoder, PretrainedTextEncoderIsCopiedFromACheckpoint) {
  torch::manual_seed(3);
  auto net = TinyTemos(0.1);
  const std::string dir = ::testing::TempDir() + "/pretrained_text";
  std::filesystem::create_directories(dir);
  torch::serialize::OutputArchive out;
  net->save(out);
  out.save_to(dir + "/model.pt");
  net->text_encoder()->SaveExtras(dir);
  const nlohmann::json options = net->text_encoder()->options().ToJson();
  std::ofstream(dir + "/model.json")
      << nlohmann::json{{"config", {{"variant", "tmr"}, {"model", {{"text_encoder", options}}}}}}
             .dump();

  torch::manual_seed(99);  // other initial weights, no tokenizer yet
  nn::TextEncoder encoder(nn::TextEncoderOptions::FromJson(options));
  EXPECT_FALSE(encoder->fitted());
  EXPECT_EQ(nn::LoadPretrainedTextEncoder(encoder, dir, {}, true), dir);
  EXPECT_TRUE(encoder->fitted());
  net->eval();
  encoder->eval();
  torch::NoGradGuard no_grad;
  const std::vector<std::string> texts = {"walk forward", "wave the right hand"};
  EXPECT_TRUE(
      torch::equal(encoder->forward(texts).tokens, net->text_encoder()->forward(texts).tokens));
  for (const auto& item : encoder->named_parameters())
    EXPECT_EQ(item.value().requires_grad(), item.key() == "separator") << item.key();

  nn::TextEncoder tuned(nn::TextEncoderOptions::FromJson(options));
  nn::LoadPretrainedTextEncoder(tuned, "input", {::testing::TempDir() + "/nothing", dir},
                                false);  // found among the inputs
  for (const auto& item : tuned->named_parameters())
    EXPECT_TRUE(item.value().requires_grad()) << item.key();

  nlohmann::json wider = options;
  wider["dim"] = 64;
  nn::TextEncoder other(nn::TextEncoderOptions::FromJson(wider));
  try {
    nn::LoadPretrainedTextEncoder(other, dir, {}, true);
    ADD_FAILURE() << "a text encoder of other settings was loaded";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(dir), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("same text_encoder settings"), std::string::npos)
        << e.what();
  }
  EXPECT_THROW(
      nn::LoadPretrainedTextEncoder(encoder, "input", {::testing::TempDir() + "/nothing"}, true),
      std::invalid_argument);
}

TEST(TextEncoder, TokenizerIsDeterministicAndRoundTrips) {
  nn::Tokenizer a, b;
  const std::vector<std::string> texts = {"walk forward slowly", "wave the right hand",
                                          "walking forwards", "jump in place"};
  a.Train(texts, 80);
  b.Train(texts, 80);
  EXPECT_EQ(a.serialized(), b.serialized());
  nn::Tokenizer c;
  c.Load(a.serialized());
  EXPECT_EQ(c.Encode("walk the right hand forward", 32),
            a.Encode("walk the right hand forward", 32));
  EXPECT_LE(a.Encode("walk the right hand forward", 3).size(), 3u);
  for (int64_t id : a.Encode("zzz unseen", 32)) EXPECT_GT(id, 0);  // never the padding id
}

}  // namespace
}  // namespace motionpipe
