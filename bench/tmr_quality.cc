#include "tmr_quality.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <numeric>
#include <sstream>
#include <string>
#include <vector>

#include "../plugins/common/fused.h"
#include "../plugins/common/precision.h"
#include "../plugins/common/threads.h"
#include "../plugins/common/train_order.h"
#include "../plugins/temos_sinc/sinc_data.h"
#include "../plugins/temos_sinc/temos.h"
#include "bench_util.h"
#include "motionpipe/base/random.h"
#include "motionpipe/eval/metrics.h"
#include "motionpipe/formats/npy.h"
#include "motionpipe/sinc/spans.h"

namespace motionpipe::bench {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// The demo's evaluator stage (configs/demo.yaml `evaluator`): its model, data and schedule.
constexpr int64_t kBatch = 32, kMaxFrames = 40, kScheduleSteps = 3600, kWarmup = 100;
constexpr double kFps = 10, kLr = 5e-4, kWeightDecay = 0.01, kClip = 1.0;
constexpr uint64_t kRetrievalSeed = 1;

// The evaluator's model at `size` (the demo's: latent 128, 2 layers, 4 heads, feed-forward 512, a
// one-layer learned text encoder).
json ModelConfig(const TemosSize& size) {
  return {{"latent", size.latent},
          {"layers", size.layers},
          {"heads", size.heads},
          {"ff", size.ff},
          {"dropout", 0.1},
          {"contrastive", 0.1},  // variant tmr
          {"text_encoder",
           {{"kind", "learned"}, {"layers", size.text_layers}, {"vocab", 800}, {"ff", size.ff}}}};
}

const TemosSize& SizeNamed(const std::string& name) {
  std::string names;
  for (const auto& size : TemosSizes()) {
    if (size.name == name) return size;
    names += (names.empty() ? "" : ", ") + size.name;
  }
  std::fprintf(stderr, "tmr_quality: --quality-size %s: not a size (%s)\n", name.c_str(),
               names.c_str());
  std::exit(2);
}

// The train stage's learning rate (plugins/common/train_order.h) with the evaluator stage's
// settings.
double LearningRate(int64_t step) {
  return nn::LearningRateSchedule{kLr, 0, kWarmup, kScheduleSteps, true}.At(step);
}

std::string EnsureSpans(const QualityArgs& a) {
  if (!a.spans.empty()) return a.spans;
  // The demo's corpus and singles stages (configs/demo.yaml), nothing else.
  const std::string root = a.dir + "/job", pipeline = a.dir + "/corpus.yaml";
  fs::remove_all(root);
  std::ofstream(pipeline)
      << "name: tmr_quality\noutput_root: " << root << "\nseed: 1\nstages:\n"
      << "  corpus: {kind: corpus, params: {clips: 2500, triplets: 0, shard_size: 250, "
         "min_seconds: 2, max_seconds: 4, manner_words: 1}}\n"
      << "  singles: {kind: singles, inputs: [corpus], params: {labeler: lexicon}}\n";
  Run(std::string(MOTIONPIPE_BINARY) + " run " + pipeline + " --workers 2 --threads 1 -q 2>&1");
  for (const auto& entry : fs::recursive_directory_iterator(root))
    if (entry.path().filename() == "spans.npz") return entry.path().string();
  std::fprintf(stderr, "tmr_quality: the singles stage wrote no spans.npz under %s\n",
               root.c_str());
  std::exit(1);
}

// Arrays of one kind over the steps, each step's slice zero-padded to a fixed shape.
struct Stream {
  std::vector<float> features, eps, lr;
  std::vector<uint8_t> padding, duplicate;
  std::vector<int64_t> tokens, frames, token_length;
};

void SaveFloat(const std::string& path, std::vector<int64_t> shape, const std::vector<float>& v) {
  SaveNpy(path, NpyArray::Float32(std::move(shape), v));
}

std::vector<float> Floats(const torch::Tensor& t) {
  const auto c = t.to(torch::kFloat).contiguous();
  return {c.data_ptr<float>(), c.data_ptr<float>() + c.numel()};
}

// The train stage's batch of `step` for one rank (plugins/train BatchOf, through the same
// nn::EpochOrder).
struct StepBatch {
  plugin::Batch batch;
  std::vector<std::vector<std::string>> groups;
};

class BatchStream {
 public:
  BatchStream(temos::SincDataset& data, uint64_t seed)
      : data_(data), order_(data.size(), kBatch, seed) {}
  StepBatch Of(int64_t step) {
    StepBatch out{data_.Get(order_.Indices(step), order_.BatchSeed(step)), {}};
    out.batch.tensors["example_seed"] = torch::tensor(order_.ExampleSeeds(step), torch::kInt64);
    for (const auto& t : out.batch.texts) out.groups.push_back({t});
    return out;
  }

 private:
  temos::SincDataset& data_;
  nn::EpochOrder order_;
};

// The test split's single actions as the evaluation scores them (each whole, at the network's
// rate, normalised with the training statistics; texts as given).
struct TestSet {
  torch::Tensor features, padding, tokens;
  std::vector<std::vector<std::string>> groups;
};

eval::Embeddings ToEmbeddings(const torch::Tensor& rows) {
  const auto d = rows.to(torch::kDouble).contiguous();
  return {d.size(0), d.size(1),
          std::vector<double>(d.data_ptr<double>(), d.data_ptr<double>() + d.numel())};
}

double TextToMotionR1(const torch::Tensor& text, const torch::Tensor& motion) {
  // As the evaluation (stages/eval_generate.cc): batches of 32, or one of every row when fewer.
  const int64_t batch = std::min<int64_t>(kBatch, text.size(0));
  const auto scores =
      eval::Retrieval(ToEmbeddings(text), ToEmbeddings(motion), batch, kRetrievalSeed);
  if (!scores.ok()) {
    std::fprintf(stderr, "tmr_quality: %s\n", scores.status().message().c_str());
    std::exit(1);
  }
  return scores->r1;
}

torch::Tensor LoadRows(const std::string& path) {
  auto array = ReadNpy(path);
  if (!array.ok()) {
    std::fprintf(stderr, "tmr_quality: %s\n", array.status().message().c_str());
    std::exit(1);
  }
  auto values = array->ToFloat32(path);
  if (!values.ok() || array->shape.size() != 2) {
    std::fprintf(stderr, "tmr_quality: %s: not the 2-d float array the reference writes\n",
                 path.c_str());
    std::exit(1);
  }
  return torch::tensor(*values).view({array->shape[0], array->shape[1]});
}

struct Checkpoint {
  int64_t step = 0;
  double seconds = 0, r1 = 0;
};

// The first checkpoint at or above the bar, or nullptr.
const Checkpoint* FirstAtBar(const std::vector<Checkpoint>& run, double bar) {
  for (const auto& c : run)
    if (c.r1 >= bar) return &c;
  return nullptr;
}

// The reference's inputs in a.dir: the initial weights, the test set and every step's batch as
// `stream` draws it. Returns the first batch's loss with dropout off at the initial weights (the
// same model's figure beside the reference's).
double WriteReferenceInputs(const QualityArgs& a, temos::Temos& net, const TestSet& test,
                            BatchStream& stream) {
  const int64_t latent = net->options().latent;
  const std::string init = a.dir + "/init";
  fs::remove_all(init);
  fs::create_directories(init);
  for (const auto& p : net->named_parameters()) {
    std::vector<int64_t> shape(p.value().sizes().begin(), p.value().sizes().end());
    SaveFloat(init + "/" + p.key() + ".npy", shape, Floats(p.value()));
  }
  SaveFloat(a.dir + "/test_features.npy",
            {test.features.size(0), test.features.size(1), test.features.size(2)},
            Floats(test.features));
  const auto test_padding = test.padding.to(torch::kUInt8).contiguous();
  SaveNpy(a.dir + "/test_padding.npy",
          NpyArray::Bool(
              {test.padding.size(0), test.padding.size(1)},
              std::vector<uint8_t>(test_padding.data_ptr<uint8_t>(),
                                   test_padding.data_ptr<uint8_t>() + test_padding.numel())));
  const auto test_tokens = test.tokens.contiguous();
  SaveNpy(
      a.dir + "/test_tokens.npy",
      NpyArray::Int64({test.tokens.size(0), test.tokens.size(1)},
                      std::vector<int64_t>(test_tokens.data_ptr<int64_t>(),
                                           test_tokens.data_ptr<int64_t>() + test_tokens.numel())));
  const int64_t max_tokens = net->text_encoder()->options().max_tokens;
  Stream s;
  double first_eval_loss = 0;
  for (int64_t step = 0; step < a.steps; ++step) {
    const StepBatch sb = stream.Of(step);
    const auto& features = sb.batch.tensors.at("features");
    const auto& padding = sb.batch.tensors.at("padding");
    const int64_t frames = features.size(0);
    auto f = torch::zeros({kMaxFrames, kBatch, temos::kFeatureDim});
    f.narrow(0, 0, frames).copy_(features);
    auto pad = torch::ones({kBatch, kMaxFrames}, torch::kBool);
    pad.narrow(1, 0, frames).copy_(padding);
    const auto ids = net->text_encoder()->TokenIds(sb.batch.texts);
    auto tok = torch::zeros({kBatch, max_tokens}, torch::kInt64);
    tok.narrow(1, 0, ids.size(1)).copy_(ids);
    const auto eps = temos::ExampleNoise(sb.batch.tensors.at("example_seed"), 2, latent);
    const auto dup = temos::NearDuplicates(sb.groups, net->options().duplicate_threshold)
                         .to(torch::kUInt8)
                         .contiguous();
    const auto append = [](auto& to, const auto& from) {
      to.insert(to.end(), from.begin(), from.end());
    };
    append(s.features, Floats(f));
    append(s.eps, Floats(eps));
    const auto pad8 = pad.to(torch::kUInt8).contiguous();
    append(s.padding,
           std::vector<uint8_t>(pad8.data_ptr<uint8_t>(), pad8.data_ptr<uint8_t>() + pad8.numel()));
    append(s.duplicate,
           std::vector<uint8_t>(dup.data_ptr<uint8_t>(), dup.data_ptr<uint8_t>() + dup.numel()));
    append(s.tokens,
           std::vector<int64_t>(tok.data_ptr<int64_t>(), tok.data_ptr<int64_t>() + tok.numel()));
    s.frames.push_back(frames);
    s.token_length.push_back(ids.size(1));
    s.lr.push_back(static_cast<float>(LearningRate(step)));
    if (step == 0) {  // the same model: the first batch's loss with dropout off, initial weights
      torch::NoGradGuard no_grad;
      net->eval();
      first_eval_loss =
          net->Losses(sb.groups, features, padding, sb.batch.tensors.at("example_seed"))
              .at("loss")
              .item<double>();
      net->train();
    }
  }
  const int64_t n = a.steps;
  SaveFloat(a.dir + "/features.npy", {n, kMaxFrames, kBatch, temos::kFeatureDim}, s.features);
  SaveFloat(a.dir + "/eps.npy", {n, 2, kBatch, latent}, s.eps);
  SaveFloat(a.dir + "/lr.npy", {n}, s.lr);
  SaveNpy(a.dir + "/padding.npy", NpyArray::Bool({n, kBatch, kMaxFrames}, s.padding));
  SaveNpy(a.dir + "/duplicate.npy", NpyArray::Bool({n, kBatch, kBatch}, s.duplicate));
  SaveNpy(a.dir + "/tokens.npy", NpyArray::Int64({n, kBatch, max_tokens}, s.tokens));
  SaveNpy(a.dir + "/frames.npy", NpyArray::Int64({n}, s.frames));
  SaveNpy(a.dir + "/token_length.npy", NpyArray::Int64({n}, s.token_length));

  return first_eval_loss;
}

// Our trainer: the train stage's step (plugins/train Step: the forward pass under `precision`) on
// `stream`, timed without the test encodings; the test R@1 from the untrained weights on, every
// a.every steps. *first_loss: the first step's training loss.
std::vector<Checkpoint> TrainOurs(const QualityArgs& a, temos::Temos& net, const TestSet& test,
                                  BatchStream& stream, nn::Precision precision,
                                  double* first_loss) {
  std::vector<torch::Tensor> params;
  for (auto& p : net->parameters())
    if (p.requires_grad()) params.push_back(p);
  torch::optim::AdamW optimizer(
      params, torch::optim::AdamWOptions(kLr).betas({0.9, 0.999}).weight_decay(kWeightDecay));
  std::vector<Checkpoint> cpp;
  // The test R@1 of the current weights (eval mode: no draws, so training is unchanged by it).
  const auto score = [&] {
    torch::NoGradGuard no_grad;
    net->eval();
    const auto t = net->EncodeText(test.groups, false).mu;
    const auto m = net->EncodeMotion(test.features, test.padding, false).mu;
    net->train();
    return TextToMotionR1(t, m);
  };
  cpp.push_back({0, 0, score()});  // the untrained yardstick: the same weights as the reference's
  double seconds = 0;
  net->train();
  for (int64_t step = 0; step < a.steps; ++step) {
    const StepBatch sb = stream.Of(step);
    const auto started = Clock::now();
    torch::manual_seed(MixSeed(a.seed, static_cast<uint64_t>(step)));
    std::map<std::string, torch::Tensor> losses;
    {
      const nn::MixedPrecision autocast(precision);
      losses = net->Losses(sb.groups, sb.batch.tensors.at("features"),
                           sb.batch.tensors.at("padding"), sb.batch.tensors.at("example_seed"));
    }
    optimizer.zero_grad();
    losses.at("loss").backward();
    for (auto& group : optimizer.param_groups())
      static_cast<torch::optim::AdamWOptions&>(group.options()).lr(LearningRate(step));
    nn::AdamWStep(optimizer, kClip);
    seconds += Since(started);
    if (step == 0) *first_loss = losses.at("loss").item<double>();
    if ((step + 1) % a.every == 0 || step + 1 == a.steps)
      cpp.push_back({step + 1, seconds, score()});
  }

  return cpp;
}

// The PyTorch-Python reference (bench/reference/tmr_ref.py) trained on the inputs in a.dir and
// scored as ours. *first_eval_loss: its first batch's loss with dropout off, initial weights.
std::vector<Checkpoint> TrainReference(const QualityArgs& a, const TemosSize& size, int64_t latent,
                                       int64_t vocab, bool bf16, double* first_eval_loss) {
  std::vector<Checkpoint> python;
  for (const auto& entry : fs::directory_iterator(a.dir))  // an earlier run's embeddings
    if (entry.path().filename().string().rfind("python_", 0) == 0) fs::remove(entry.path());
  std::ostringstream command;
  command << "OMP_NUM_THREADS=" << a.threads << " OPENBLAS_NUM_THREADS=" << a.threads
          << " /usr/bin/python3 " << MOTIONPIPE_SOURCE_DIR << "/bench/reference/tmr_ref.py --dir "
          << a.dir << " --latent " << latent << " --layers " << size.layers << " --heads "
          << size.heads << " --ff " << size.ff << " --text-layers " << size.text_layers
          << " --vocab " << vocab << " --steps " << a.steps << " --every " << a.every
          << " --threads " << a.threads << (bf16 ? " --bf16" : "") << " 2>&1";
  const std::string out = Run(command.str());
  const json result = json::parse(out.substr(out.rfind("\n{") + 1));
  *first_eval_loss = result.at("first_eval_loss").get<double>();
  for (const auto& c : result.at("checkpoints")) {
    const int64_t step = c.at("step").get<int64_t>();
    const std::string prefix = a.dir + "/python_" + std::to_string(step);
    python.push_back(
        {step, c.at("seconds").get<double>(),
         TextToMotionR1(LoadRows(prefix + "_text.npy"), LoadRows(prefix + "_motion.npy"))});
  }
  return python;
}

}  // namespace

void BenchTimeToQuality(const QualityArgs& a) {
  const TemosSize& size = SizeNamed(a.size);
  fs::create_directories(a.dir);
  const std::string spans = EnsureSpans(a);
  auto read = sinc::ReadSpans(spans);
  if (!read.ok()) {
    std::fprintf(stderr, "tmr_quality: %s\n", read.status().message().c_str());
    std::exit(1);
  }
  auto table = std::make_shared<sinc::SpanTable>(std::move(*read));
  nn::SetTorchThreads(static_cast<int>(a.threads));

  // As the train stage: the seed, then the model, then the data (tokenizer and statistics).
  torch::manual_seed(a.seed);
  temos::Temos net(temos::TemosOptions::FromJson(ModelConfig(size)));
  temos::SincDataOptions options;
  options.spans = spans;
  options.real_pairs = true;
  options.synthetic_p = 0;
  options.max_frames = kMaxFrames;
  options.fps = kFps;
  temos::SincDataset train(table, options);
  net->text_encoder()->Fit(train.AllTexts());
  const auto [mean, stddev] = train.ComputeStats();
  train.SetStats(mean, stddev);
  temos::SincDataOptions test_options = options;
  test_options.split = "test";
  test_options.real_pairs = false;
  test_options.max_frames = 1 << 20;
  test_options.augment_texts = false;
  temos::SincDataset test_data(table, test_options);
  test_data.SetStats(mean, stddev);
  TestSet test;
  {
    std::vector<int64_t> all(static_cast<size_t>(test_data.size()));
    std::iota(all.begin(), all.end(), 0);
    const plugin::Batch b = test_data.Get(all, 0);
    test.features = b.tensors.at("features");
    test.padding = b.tensors.at("padding");
    test.tokens = net->text_encoder()->TokenIds(b.texts);
    for (const auto& t : b.texts) test.groups.push_back({t});
  }
  const int64_t latent = net->options().latent, vocab = net->text_encoder()->options().vocab;

  BatchStream stream(train, a.seed);
  const double first_eval_loss = WriteReferenceInputs(a, net, test, stream);
  const nn::Precision precision = nn::EffectivePrecision(
      a.bf16 ? nn::Precision::kBf16 : nn::Precision::kFloat32, nn::CpuHasNativeBf16());
  double first_loss = 0, python_eval_loss = 0;
  const std::vector<Checkpoint> cpp = TrainOurs(a, net, test, stream, precision, &first_loss);
  const std::vector<Checkpoint> python =
      a.reference ? TrainReference(a, size, latent, vocab, precision == nn::Precision::kBf16,
                                   &python_eval_loss)
                  : std::vector<Checkpoint>{};

  std::printf(
      "\ntime to quality: the demo's TMR evaluator (10 fps, batch 32, lr 5e-4 on the 3,600-step "
      "schedule) at %s size (latent %lld, %lld layers, feed-forward %lld, %lld text layer(s)), "
      "seed %llu, %s, %lld thread(s), %lld test singles; text-to-motion R@1 in batches of "
      "32\n",
      size.name.c_str(), static_cast<long long>(size.latent), static_cast<long long>(size.layers),
      static_cast<long long>(size.ff), static_cast<long long>(size.text_layers),
      static_cast<unsigned long long>(a.seed), nn::PrecisionName(precision),
      static_cast<long long>(a.threads), static_cast<long long>(test.features.size(1)));
  std::printf(
      "same model: the first batch's loss, dropout off, initial weights: C++ %.6f, Python %.6f; "
      "C++ first training loss %.6f\n",
      first_eval_loss, python_eval_loss, first_loss);
  std::printf("%6s %10s %8s %10s %8s\n", "step", "C++ s", "C++ R@1", "Py s", "Py R@1");
  for (size_t k = 0; k < cpp.size(); ++k) {
    std::printf("%6lld %10.1f %8.1f", static_cast<long long>(cpp[k].step), cpp[k].seconds,
                cpp[k].r1);
    if (k < python.size()) std::printf(" %10.1f %8.1f", python[k].seconds, python[k].r1);
    std::printf("\n");
  }
  const auto describe = [&](const std::vector<Checkpoint>& run) {
    const Checkpoint* c = FirstAtBar(run, a.bar);
    char line[96];
    if (c)
      std::snprintf(line, sizeof line, "%.2f min (step %lld)", c->seconds / 60,
                    static_cast<long long>(c->step));
    else
      std::snprintf(line, sizeof line, "not within %lld steps", static_cast<long long>(a.steps));
    return std::string(line);
  };
  std::printf("minutes of training to R@1 %.0f: C++ %s", a.bar, describe(cpp).c_str());
  if (a.reference) {
    std::printf(", Python %s", describe(python).c_str());
    const Checkpoint *c = FirstAtBar(cpp, a.bar), *p = FirstAtBar(python, a.bar);
    if (c && p) std::printf(", ratio Python/C++ %.2f", p->seconds / c->seconds);
  }
  std::printf("\n");
  std::fflush(stdout);
}

}  // namespace motionpipe::bench
