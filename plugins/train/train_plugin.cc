// The `train` stage: trains any model plugin (factory kind "model") data-parallel over a gang of
// ranks with torch's own c10d Gloo process group (rendezvous: a c10d TCPStore served by rank 0,
// whose address rank 0 publishes in the gang's rendezvous file the coordinator names; or a
// FileStore there), with AdamW, a warm-up + cosine schedule, gradient clipping, atomic checkpoints
// every K steps that a restarted gang resumes from, and the loss curve in CSV and on the worker's
// /metrics.
//
// params: model (plugin model name), config (the model's config), data (the model's data config),
//   steps (0: the untrained model), batch_size (global: split across ranks), lr, weight_decay,
//   betas [b1, b2], warmup, schedule (cosine | constant), min_lr, clip_grad, checkpoint_every,
//   keep_checkpoints, log_every, seed, validate_every (steps between validations on the held-out
//   split; 0 = none), val_batches (4), keep (last | best: the output model is the one with the
//   lowest validation loss), gloo_host (the address other ranks reach this one on; default
//   127.0.0.1), store (tcp | file; default tcp), collective_timeout (seconds, default 120),
//   precision (float32 | bf16: the forward pass under bf16 autocast, plugins/common/precision.h;
//   weights, gradients and optimiser state stay float32; on a CPU without native bf16 products,
//   bf16 runs as float32 with a warning, and rank-R.json says which ran), ema (decay of an
//   exponential moving average of the weights, as DDPM, DiT and EDM sample from; 0, the default:
//   none. Rank 0 keeps it, validates it and writes it as the model; a step's decay is
//   min(ema, (1 + step) / (10 + step)), so the first steps' weights do not dominate it)
//
// Rank r of W takes every W-th example of each global batch, and the gradients are averaged over
// the ranks (all-reduce of one flattened buffer), so W ranks take the same step as one rank on the
// whole batch. Rank 0 writes the checkpoints (state_dir/ckpt-NNNNNNNN, then state_dir/latest) and,
// at the end, the trained model into its output: model/ (model.pt, model.json, extras),
// state_dict.pt (loadable by Python's torch.load), losses.csv (every term of every step) and, when
// validating, val_losses.csv (step, val_loss, the wall seconds of training so far across resumes,
// and val_<term> for the model's other terms on the held-out batches).
#include <omp.h>
#include <torch/torch.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <numeric>
#include <optional>
#include <random>
#include <sstream>
#include <thread>
#include <torch/csrc/distributed/c10d/FileStore.hpp>
#include <torch/csrc/distributed/c10d/ProcessGroupGloo.hpp>
#include <torch/csrc/distributed/c10d/TCPStore.hpp>

#include "../api/model.hpp"
#include "../api/plugin.hpp"
#include "../common/fused.h"
#include "../common/precision.h"
#include "../common/threads.h"
#include "../common/train_order.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/job_layout.h"
#include "motionpipe/base/random.h"

namespace motionpipe::train {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using plugin::Task;

struct Options {
  std::string model;
  json config, data;
  int64_t steps = 1000, batch_size = 32, warmup = 100, checkpoint_every = 200, keep_checkpoints = 2,
          log_every = 10;
  int64_t validate_every = 0, val_batches = 4;
  std::string keep = "last";
  double lr = 3e-4, weight_decay = 0.01, beta1 = 0.9, beta2 = 0.999, min_lr = 0, clip_grad = 1.0;
  double ema = 0;
  std::string schedule = "cosine";
  nn::Precision requested_precision = nn::Precision::kFloat32;  // params.precision
  nn::Precision precision = nn::Precision::kFloat32;            // what this CPU runs
  uint64_t seed = 1;
  std::string gloo_host = "127.0.0.1";
  std::string store = "tcp";
  int collective_timeout = 120;
  static Options FromTask(const Task& task) {
    const json& p = task.params();
    Options o;
    o.model = p.at("model").get<std::string>();
    o.config = p.value("config", json::object());
    o.data = p.value("data", json::object());
    o.steps = p.value("steps", o.steps);
    o.batch_size = p.value("batch_size", o.batch_size);
    o.warmup = p.value("warmup", o.warmup);
    o.checkpoint_every = p.value("checkpoint_every", o.checkpoint_every);
    o.keep_checkpoints = p.value("keep_checkpoints", o.keep_checkpoints);
    o.log_every = p.value("log_every", o.log_every);
    o.validate_every = p.value("validate_every", o.validate_every);
    o.val_batches = p.value("val_batches", o.val_batches);
    o.keep = p.value("keep", o.keep);
    if (o.keep != "last" && o.keep != "best")
      throw plugin::BadInput("params.keep must be last or best");
    if (o.keep == "best" && o.validate_every <= 0)
      throw plugin::BadInput("params.keep: best needs params.validate_every > 0");
    if (o.validate_every < 0 || o.val_batches < 1)
      throw plugin::BadInput("params.validate_every must be >= 0 and params.val_batches positive");
    o.lr = p.value("lr", o.lr);
    o.weight_decay = p.value("weight_decay", o.weight_decay);
    if (p.contains("betas")) {
      o.beta1 = p["betas"].at(0).get<double>();
      o.beta2 = p["betas"].at(1).get<double>();
    }
    o.min_lr = p.value("min_lr", o.min_lr);
    o.clip_grad = p.value("clip_grad", o.clip_grad);
    o.schedule = p.value("schedule", o.schedule);
    o.ema = p.value("ema", o.ema);
    if (!(o.ema >= 0 && o.ema < 1))
      throw plugin::BadInput("params.ema must be in [0, 1) (0: no moving average of the weights)");
    try {
      o.requested_precision =
          nn::ParsePrecision(p.value("precision", std::string("float32")), "params.precision");
      o.precision = nn::EffectivePrecision(o.requested_precision, nn::CpuHasNativeBf16());
    } catch (const std::invalid_argument& e) {
      throw plugin::BadInput(e.what());
    }
    o.seed = p.value("seed", task.spec.value("seed", uint64_t{1}));
    o.gloo_host = p.value("gloo_host", o.gloo_host);
    o.store = p.value("store", o.store);
    o.collective_timeout = p.value("collective_timeout", o.collective_timeout);
    if (o.store != "tcp" && o.store != "file")
      throw plugin::BadInput("params.store must be tcp or file");
    // steps: 0 writes the initial weights (with the data's statistics and tokenizer): the untrained
    // yardstick row of an evaluation.
    if (o.steps < 0 || o.batch_size < 1)
      throw plugin::BadInput("params.steps must be >= 0 and params.batch_size positive");
    if (o.schedule != "cosine" && o.schedule != "constant")
      throw plugin::BadInput("params.schedule must be cosine or constant");
    return o;
  }
  json ToJson() const {
    return {{"model", model},
            {"steps", steps},
            {"batch_size", batch_size},
            {"warmup", warmup},
            {"lr", lr},
            {"weight_decay", weight_decay},
            {"betas", {beta1, beta2}},
            {"schedule", schedule},
            {"precision", nn::PrecisionName(requested_precision)},
            {"precision_run", nn::PrecisionName(precision)},
            {"min_lr", min_lr},
            {"clip_grad", clip_grad},
            {"ema", ema},
            {"checkpoint_every", checkpoint_every},
            {"seed", seed},
            {"validate_every", validate_every},
            {"val_batches", val_batches},
            {"keep", keep}};
  }
};

double LearningRate(const Options& o, int64_t step) {
  return nn::LearningRateSchedule{o.lr, o.min_lr, o.warmup, o.steps, o.schedule == "cosine"}.At(
      step);
}

// The model through its plugin's factory (and its destructor through the same factory).
struct ModelHandle {
  const mp_object_factory* factory = nullptr;
  plugin::Model* model = nullptr;
  ~ModelHandle() {
    if (model) factory->destroy(model);
  }
};

void SaveModule(torch::nn::Module& module, const std::string& path) {
  torch::serialize::OutputArchive archive;
  module.save(archive);
  archive.save_to(path + ".tmp");
  fs::rename(path + ".tmp", path);
}

void LoadModule(torch::nn::Module& module, const std::string& path) {
  torch::serialize::InputArchive archive;
  archive.load_from(path);
  module.load(archive);
}

// A state dict (parameters and buffers by name) that Python's torch.load reads.
void ExportStateDict(torch::nn::Module& module, const std::string& path) {
  c10::Dict<std::string, at::Tensor> dict;
  for (const auto& item : module.named_parameters())
    dict.insert(item.key(), item.value().detach().clone());
  for (const auto& item : module.named_buffers())
    dict.insert(item.key(), item.value().detach().clone());
  const std::vector<char> bytes = torch::pickle_save(c10::IValue(dict));
  const Status s = WriteFileAtomic(path, std::string(bytes.begin(), bytes.end()));
  if (!s.ok()) throw std::runtime_error(s.message());
}

// Writes the model as a checkpoint directory others can run (generator factories read it).
void WriteModelDir(plugin::Model& model, const Options& options, int64_t step,
                   const std::string& dir) {
  fs::create_directories(dir);
  SaveModule(model.Module(), layout::ModelWeightsFile(dir));
  model.SaveExtras(dir);
  const json meta = {{"name", model.Name()},
                     {"config", model.Config()},
                     {"step", step},
                     {"trainer", options.ToJson()}};
  const Status s = WriteFileAtomic(layout::ModelConfigFile(dir), meta.dump(1) + "\n");
  if (!s.ok()) throw std::runtime_error(s.message());
}

struct Checkpoint {
  int64_t step = 0;
  std::string dir;
  double seconds = 0;  // wall seconds of training up to it (0 from a version that did not record)
};

std::optional<Checkpoint> LatestCheckpoint(const std::string& state_dir) {
  auto text = ReadFile(state_dir + "/latest");
  if (!text.ok()) return std::nullopt;
  std::string name = *text;
  while (!name.empty() && (name.back() == '\n' || name.back() == ' ')) name.pop_back();
  const std::string dir = state_dir + "/" + name;
  auto meta = ReadFile(dir + "/trainer.json");
  if (!meta.ok()) return std::nullopt;
  const json trainer = json::parse(*meta);
  return Checkpoint{trainer.value("step", int64_t{0}), dir, trainer.value("seconds", 0.0)};
}

// The losses CSV keeps exactly the rows of steps before `step` (a resumed run continues the curve).
void TruncateCsv(const std::string& path, int64_t step) {
  std::ifstream in(path);
  if (!in) return;
  std::string header, line, kept;
  std::getline(in, header);
  kept = header + "\n";
  while (std::getline(in, line)) {
    if (line.empty()) continue;
    if (std::stoll(line.substr(0, line.find(','))) < step) kept += line + "\n";
  }
  const Status s = WriteFileAtomic(path, kept, false);
  if (!s.ok()) throw std::runtime_error(s.message());
}

// The gang's key-value store. tcp: rank 0 serves a TCPStore on an ephemeral port of gloo_host and
// publishes "host port" in the rendezvous file (fresh for every gang dispatch); the other ranks
// wait for it and connect. file: a FileStore at the rendezvous path (needs a shared file system).
c10::intrusive_ptr<c10d::Store> OpenStore(const Options& options, const std::string& rendezvous,
                                          int rank, int world, const Task& task) {
  const auto timeout = std::chrono::seconds(options.collective_timeout);
  if (options.store == "file") return c10::make_intrusive<c10d::FileStore>(rendezvous, world);
  c10d::TCPStoreOptions tcp;
  tcp.numWorkers = static_cast<size_t>(world);
  tcp.timeout = timeout;
  const std::string address = rendezvous + ".tcp";
  if (rank == 0) {
    tcp.isServer = true;
    tcp.port = 0;
    tcp.waitWorkers = false;
    auto store = c10::make_intrusive<c10d::TCPStore>(options.gloo_host, tcp);
    const Status s =
        WriteFileAtomic(address, options.gloo_host + " " + std::to_string(store->getPort()) + "\n");
    if (!s.ok()) throw std::runtime_error(s.message());
    return store;
  }
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (true) {
    if (auto text = ReadFile(address); text.ok()) {
      std::istringstream in(*text);
      std::string host;
      int port = 0;
      if (in >> host >> port && port > 0) {
        tcp.port = static_cast<uint16_t>(port);
        return c10::make_intrusive<c10d::TCPStore>(host, tcp);
      }
    }
    if (task.cancelled())
      throw std::runtime_error("cancelled while waiting for rank 0's store address in " + address);
    if (std::chrono::steady_clock::now() > deadline)
      throw std::runtime_error("rank 0 did not publish its store address in " + address);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

// The mean of each of the model's terms over `batches` fixed batches of the held-out split ("loss",
// the validation loss, and what the model logs beside it, e.g. TEMOS's retrieval_r1): the same
// examples and the same per-example draws (diffusion steps, noise, reparameterisation) at every
// validation, dropout off.
std::map<std::string, double> Validate(plugin::Model& model, plugin::Dataset& val,
                                       const Options& options) {
  torch::NoGradGuard no_grad;
  model.Module().eval();
  std::map<std::string, double> total;
  const int64_t n = val.size();
  for (int64_t b = 0; b < options.val_batches; ++b) {
    std::vector<int64_t> indices;
    std::vector<int64_t> example_seeds;
    for (int64_t k = 0; k < options.batch_size; ++k) {
      indices.push_back((b * options.batch_size + k) % n);
      example_seeds.push_back(
          static_cast<int64_t>(MixSeed(MixSeed(options.seed, 0x7661ull),
                                       static_cast<uint64_t>(b * options.batch_size + k)) >>
                               1));
    }
    plugin::Batch batch =
        val.Get(indices, MixSeed(options.seed, 0x76616cull + static_cast<uint64_t>(b)));
    batch.tensors["example_seed"] = torch::tensor(example_seeds, torch::kInt64);
    torch::manual_seed(MixSeed(options.seed, 0x76616c00ull + static_cast<uint64_t>(b)));
    for (const auto& [name, value] : model.Losses(batch, 0)) total[name] += value.item<double>();
  }
  model.Module().train();
  for (auto& [name, value] : total) value /= static_cast<double>(options.val_batches);
  return total;
}

// One rank of a training gang: the model, its data, the optimiser, the gang's process group and,
// on rank 0, the loss logs, the best model by validation loss and the checkpoints.
class Trainer {
 public:
  explicit Trainer(const Task& task)
      : task_(task),
        options_(Options::FromTask(task)),
        rank_(task.spec.value("index", 0)),
        world_(std::max(1, task.spec.value("world_size", 1))),
        state_dir_(task.spec.value("state_dir", std::string())),
        out_dir_(task.output_dir()),
        csv_(layout::LossesFile(state_dir_)),
        val_csv_(layout::ValLossesFile(state_dir_)),
        best_dir_(state_dir_ + "/best") {}

  void Run() {
    if (state_dir_.empty())
      throw plugin::BadInput("the train stage needs a state_dir (a coordinator that knows gangs)");
    fs::create_directories(state_dir_);
    fs::create_directories(out_dir_);
    nn::SetTorchThreads(omp_get_max_threads());
    if (options_.precision != options_.requested_precision && rank_ == 0)
      task_.Log(MP_LOG_WARN,
                "params.precision bf16: this CPU has no native bf16 products (AVX512-BF16 or "
                "AMX), where LibTorch's emulated ones cost many times float32's; training in "
                "float32");
    torch::manual_seed(options_.seed);
    CreateModel();
    MakeDatasets();
    for (auto& p : model().Module().parameters()) {
      if (p.requires_grad()) params_.push_back(p);
    }
    optimizer_ =
        std::make_unique<torch::optim::AdamW>(params_, torch::optim::AdamWOptions(options_.lr)
                                                           .betas({options_.beta1, options_.beta2})
                                                           .weight_decay(options_.weight_decay));
    const int64_t start = Resume();
    if (options_.ema > 0 && rank_ == 0 && ema_.empty())
      for (const auto& p : params_) ema_.push_back(p.detach().clone());
    JoinGang();
    started_ = std::chrono::steady_clock::now();
    model().Module().train();
    for (int64_t step = start; step < options_.steps; ++step) {
      if (task_.cancelled()) throw std::runtime_error("cancelled at step " + std::to_string(step));
      Step(step);
      if (rank_ != 0) continue;
      if (val_dataset_ && ((step + 1) % options_.validate_every == 0 || step + 1 == options_.steps))
        ValidateAndKeepBest(step);
      if ((step + 1) % options_.checkpoint_every == 0 && step + 1 < options_.steps)
        SaveCheckpoint(step);
    }
    if (log_.is_open()) log_.close();
    const double seconds = TrainingSeconds() - seconds_before_;  // this attempt's
    if (rank_ == 0) WriteOutputs();
    WriteSummary(start, seconds);
  }

 private:
  plugin::Model& model() { return *handle_.model; }

  // The model through its plugin's factory.
  void CreateModel() {
    handle_.factory = task_.Factory("model", options_.model);
    if (!handle_.factory)
      throw plugin::BadInput("no model plugin '" + options_.model + "' is loaded on this worker");
    char error[2048] = {0};
    handle_.model = static_cast<plugin::Model*>(
        handle_.factory->create(options_.config.dump().c_str(), error, sizeof error));
    if (!handle_.model)
      throw plugin::BadInput(std::string("model '") + options_.model + "': " + error);
  }

  // This rank's training data and, on rank 0 when validating, the held-out split (the other ranks
  // do not wait for it).
  void MakeDatasets() {
    plugin::DataContext data;
    data.config = options_.data;
    for (const auto& input : task_.spec["inputs"]) {
      if (!input.value("result_dir", std::string()).empty())
        data.input_dirs.push_back(input["result_dir"].get<std::string>());
      for (const auto& dir : input["dirs"]) data.input_dirs.push_back(dir.get<std::string>());
    }
    data.state_dir = state_dir_;
    data.rank = rank_;
    data.world_size = world_;
    data.seed = options_.seed;
    try {
      dataset_ = model().MakeDataset(data);
    } catch (const std::invalid_argument& e) {
      throw plugin::BadInput(e.what());
    }
    if (options_.validate_every > 0 && rank_ == 0) {
      plugin::DataContext val = data;
      val.split = "val";
      try {
        val_dataset_ = model().MakeDataset(val);
      } catch (const std::invalid_argument& e) {
        throw plugin::BadInput(std::string("validate_every: the held-out split: ") + e.what());
      }
    }
    if (options_.batch_size % world_ != 0) {
      throw plugin::BadInput("batch_size " + std::to_string(options_.batch_size) +
                             " must be divisible by world_size " + std::to_string(world_));
    }
  }

  // Resumes from the newest checkpoint of an earlier attempt of this gang; returns its step (0 for
  // a fresh start, whose logs and best model from earlier attempts are removed).
  int64_t Resume() {
    const auto latest = LatestCheckpoint(state_dir_);
    if (!latest) {
      if (rank_ == 0) {
        for (const std::string& file : {csv_, val_csv_}) fs::remove(file);
        fs::remove_all(best_dir_);
      }
      return 0;
    }
    LoadModule(model().Module(), layout::ModelWeightsFile(latest->dir));
    torch::load(*optimizer_, latest->dir + "/optimizer.pt");
    if (options_.ema > 0 && rank_ == 0) {
      if (!fs::exists(latest->dir + "/ema.pt"))
        throw plugin::BadInput(latest->dir +
                               ": no ema.pt (the checkpoint was written without params.ema)");
      torch::load(ema_, latest->dir + "/ema.pt");
    }
    const int64_t start = latest->step;
    seconds_before_ = latest->seconds;
    task_.Log(MP_LOG_INFO,
              "rank " + std::to_string(rank_) + " resumes from step " + std::to_string(start));
    if (rank_ == 0) {
      TruncateCsv(csv_, start);
      TruncateCsv(val_csv_, start + 1);  // a validation row is logged at the step it follows
      // The best model so far, if it was validated before the resumed step.
      if (auto meta = ReadFile(best_dir_ + "/best.json"); meta.ok()) {
        const json best = json::parse(*meta);
        if (best.value("step", int64_t{-1}) <= start)
          best_val_ = best.value("val_loss", best_val_),
          best_step_ = best.value("step", best_step_);
      }
    }
    return start;
  }

  // world_size > 1: the gang's Gloo process group; every rank starts from rank 0's parameters.
  void JoinGang() {
    if (world_ <= 1) return;
    const std::string rendezvous = task_.spec.value("rendezvous", std::string());
    if (rendezvous.empty())
      throw plugin::BadInput(
          "world_size > 1 but no rendezvous: run this stage through a coordinator");
    auto store = OpenStore(options_, rendezvous, rank_, world_, task_);
    auto gloo = c10d::ProcessGroupGloo::Options::create();
    gloo->devices.push_back(c10d::ProcessGroupGloo::createDeviceForHostname(options_.gloo_host));
    gloo->timeout = std::chrono::seconds(options_.collective_timeout);
    group_ = c10::make_intrusive<c10d::ProcessGroupGloo>(store, rank_, world_, gloo);
    for (auto& p : model().Module().parameters()) {
      std::vector<at::Tensor> t = {p.data()};
      group_->broadcast(t)->wait();
    }
  }

  // This rank's part of the global batch of `step`: every world-th example of an order shuffled
  // once per epoch, with each example's own seed (its place in the global batch) for models whose
  // sampling must not depend on how the batch was split over ranks.
  plugin::Batch BatchOf(int64_t step) {
    if (!order_) order_.emplace(dataset_->size(), options_.batch_size, options_.seed);
    plugin::Batch batch =
        dataset_->Get(order_->Indices(step, rank_, world_), order_->BatchSeed(step));
    batch.tensors["example_seed"] =
        torch::tensor(order_->ExampleSeeds(step, rank_, world_), torch::kInt64);
    return batch;
  }

  // Averages the gradients and the logged losses over the ranks in one all-reduce; returns the
  // averaged losses (in the order of `values`).
  torch::Tensor AllReduce(const std::vector<float>& values) {
    if (!group_) return torch::tensor(values);  // a gang of one: nothing to average
    std::vector<torch::Tensor> flat;
    for (auto& p : params_)
      flat.push_back(p.grad().defined() ? p.grad().reshape({-1}) : torch::zeros({p.numel()}));
    flat.push_back(torch::tensor(values));
    auto buffer = torch::cat(flat);
    std::vector<at::Tensor> t = {buffer};
    group_->allreduce(t)->wait();
    buffer.div_(static_cast<double>(world_));
    int64_t offset = 0;
    for (auto& p : params_) {
      if (p.grad().defined())
        p.mutable_grad().copy_(buffer.narrow(0, offset, p.numel()).view_as(p));
      offset += p.numel();
    }
    return buffer.narrow(0, offset, static_cast<int64_t>(values.size()));
  }

  // One optimiser step (gradients averaged over the gang, clipped, AdamW at the scheduled rate);
  // rank 0 logs its losses.
  void Step(int64_t step) {
    plugin::Batch batch = BatchOf(step);
    torch::manual_seed(MixSeed(options_.seed, static_cast<uint64_t>(step * world_ + rank_)));
    std::map<std::string, torch::Tensor> losses;
    {
      // The forward pass under the step's precision; backward follows the dtypes it chose.
      const nn::MixedPrecision autocast(options_.precision);
      losses = model().Losses(batch, step);
    }
    const auto loss = losses.at("loss");
    if (!std::isfinite(loss.item<double>()))
      throw std::runtime_error("loss is not finite at step " + std::to_string(step));
    optimizer_->zero_grad();
    loss.backward();
    std::vector<std::string> names;
    std::vector<float> values;
    for (const auto& [name, value] : losses) {
      names.push_back(name);
      values.push_back(value.detach().item<float>());
    }
    const torch::Tensor averaged = AllReduce(values);
    const double lr = LearningRate(options_, step);
    for (auto& group_options : optimizer_->param_groups())
      static_cast<torch::optim::AdamWOptions&>(group_options.options()).lr(lr);
    // Clipping and AdamW in one pass per parameter (LibTorch's clip_grad_norm_ and AdamW::step
    // make about ten over each; plugins/common/fused.h).
    nn::AdamWStep(*optimizer_, options_.clip_grad);
    if (!ema_.empty()) {
      const double decay = std::min(
          options_.ema, (1.0 + static_cast<double>(step)) / (10.0 + static_cast<double>(step)));
      torch::NoGradGuard no_grad;
      for (size_t k = 0; k < ema_.size(); ++k) ema_[k].lerp_(params_[k].detach(), 1.0 - decay);
    }
    last_loss_ = averaged[static_cast<int64_t>(std::find(names.begin(), names.end(), "loss") -
                                               names.begin())]
                     .item<double>();
    if (rank_ == 0) LogStep(step, lr, names, averaged);
  }

  // Runs `f` with the moving average's weights in the model (params.ema), then puts the trained
  // weights back; without it, `f` on the trained weights.
  template <class F>
  void WithAveragedWeights(F f) {
    if (ema_.empty()) return f();
    std::vector<torch::Tensor> trained;
    for (const auto& p : params_) trained.push_back(p.detach().clone());
    CopyIntoParameters(ema_);
    f();
    CopyIntoParameters(trained);
  }

  void CopyIntoParameters(const std::vector<torch::Tensor>& weights) {
    torch::NoGradGuard no_grad;
    for (size_t k = 0; k < weights.size(); ++k) params_[k].detach().copy_(weights[k]);
  }

  // Rank 0: a row of losses.csv per step, flushed (and the live metrics set) every log_every.
  void LogStep(int64_t step, double lr, const std::vector<std::string>& names,
               const torch::Tensor& averaged) {
    if (!log_.is_open()) {
      const bool fresh = !fs::exists(csv_);
      log_.open(csv_, std::ios::app);
      if (fresh) {
        log_ << "step,epoch,lr";
        for (const auto& c : names) log_ << "," << c;
        log_ << "\n";
      }
    }
    const int64_t per_epoch = std::max<int64_t>(1, dataset_->size() / options_.batch_size);
    log_ << step << "," << step / per_epoch << "," << lr;
    for (int64_t k = 0; k < static_cast<int64_t>(names.size()); ++k)
      log_ << "," << averaged[k].item<float>();
    log_ << "\n";
    if ((step + 1) % options_.log_every == 0 || step + 1 == options_.steps) {
      log_.flush();
      task_.Metric("loss", last_loss_);
      task_.Metric("step", static_cast<double>(step + 1));
      task_.Metric("lr", lr);
    }
  }

  // Wall seconds of training since step 0: this attempt's, plus those of the attempts before it up
  // to the checkpoint it resumed from (validations and checkpoints included).
  double TrainingSeconds() const {
    return seconds_before_ +
           std::chrono::duration<double>(std::chrono::steady_clock::now() - started_).count();
  }

  // Rank 0: the held-out loss after `step`, logged with the training seconds so far and the
  // model's other terms on the same batches (val_<term>: the time to a validation quality, e.g. a
  // TMR's retrieval); a new lowest loss writes best/ (atomically). With params.ema, of the moving
  // average's weights.
  void ValidateAndKeepBest(int64_t step) {
    WithAveragedWeights([&] { ValidateAndKeepBestOfTheModel(step); });
  }

  void ValidateAndKeepBestOfTheModel(int64_t step) {
    const std::map<std::string, double> terms = Validate(model(), *val_dataset_, options_);
    const double val_loss = terms.at("loss");
    const bool fresh = !fs::exists(val_csv_);
    std::ofstream val_log(val_csv_, std::ios::app);
    if (fresh) {
      val_log << "step,val_loss,seconds";
      for (const auto& term : terms)
        if (term.first != "loss") val_log << ",val_" << term.first;
      val_log << "\n";
    }
    val_log << step << "," << val_loss << "," << TrainingSeconds();
    for (const auto& [name, value] : terms)
      if (name != "loss") val_log << "," << value;
    val_log << "\n";
    task_.Metric("val_loss", val_loss);
    if (val_loss >= best_val_) return;
    best_val_ = val_loss, best_step_ = step + 1;
    fs::remove_all(best_dir_ + ".tmp");
    WriteModelDir(model(), options_, best_step_, best_dir_ + ".tmp");
    const Status s =
        WriteFileAtomic(best_dir_ + ".tmp/best.json",
                        json({{"step", best_step_}, {"val_loss", best_val_}}).dump() + "\n");
    if (!s.ok()) throw std::runtime_error(s.message());
    fs::remove_all(best_dir_);
    fs::rename(best_dir_ + ".tmp", best_dir_);
  }

  // Rank 0: state_dir/ckpt-NNNNNNNN (weights, optimiser, trainer.json) written under a temporary
  // name and renamed, `latest` pointed at it, checkpoints beyond keep_checkpoints removed.
  void SaveCheckpoint(int64_t step) {
    log_.flush();
    const int64_t per_epoch = std::max<int64_t>(1, dataset_->size() / options_.batch_size);
    const std::string name = "ckpt-" + std::to_string(100000000 + step + 1).substr(1);
    const std::string tmp = state_dir_ + "/" + name + ".tmp";
    fs::remove_all(tmp);
    fs::create_directories(tmp);
    SaveModule(model().Module(), layout::ModelWeightsFile(tmp));
    torch::save(*optimizer_, tmp + "/optimizer.pt");
    if (!ema_.empty()) torch::save(ema_, tmp + "/ema.pt");
    const Status s = WriteFileAtomic(tmp + "/trainer.json", json({{"step", step + 1},
                                                                  {"epoch", step / per_epoch},
                                                                  {"world_size", world_},
                                                                  {"seconds", TrainingSeconds()}})
                                                                    .dump() +
                                                                "\n");
    if (!s.ok()) throw std::runtime_error(s.message());
    fs::remove_all(state_dir_ + "/" + name);
    fs::rename(tmp, state_dir_ + "/" + name);
    const Status latest = WriteFileAtomic(state_dir_ + "/latest", name + "\n");
    if (!latest.ok()) throw std::runtime_error(latest.message());
    std::vector<std::string> all;
    for (const auto& entry : fs::directory_iterator(state_dir_)) {
      const std::string file = entry.path().filename().string();
      if (file.rfind("ckpt-", 0) == 0 && file.find(".tmp") == std::string::npos)
        all.push_back(file);
    }
    std::sort(all.begin(), all.end());
    for (size_t k = 0; k + static_cast<size_t>(options_.keep_checkpoints) < all.size(); ++k)
      fs::remove_all(state_dir_ + "/" + all[k]);
  }

  // Rank 0: the output model (with keep: best, the lowest validation loss's; with params.ema, the
  // moving average's weights), state_dict.pt and the loss curves.
  void WriteOutputs() {
    model().Module().eval();
    if (options_.keep == "best" && best_step_ >= 0 && best_step_ < options_.steps) {
      LoadModule(model().Module(), layout::ModelWeightsFile(best_dir_));
      WriteModelDir(model(), options_, best_step_, layout::CheckpointDir(out_dir_));
    } else {
      CopyIntoParameters(ema_);  // the moving average's weights, when params.ema keeps one
      WriteModelDir(model(), options_, options_.steps, layout::CheckpointDir(out_dir_));
    }
    ExportStateDict(model().Module(), out_dir_ + "/state_dict.pt");
    for (const std::string& file : {csv_, val_csv_}) {
      if (fs::exists(file))
        fs::copy_file(file, out_dir_ + "/" + fs::path(file).filename().string(),
                      fs::copy_options::overwrite_existing);
    }
  }

  // Every rank: rank-R.json (steps, time, throughput, final loss; rank 0 adds the best model).
  void WriteSummary(int64_t start, double seconds) {
    const int64_t trained = options_.steps - start;
    const int64_t local = options_.batch_size / world_;
    const double samples_per_second =
        static_cast<double>(trained * local) / std::max(seconds, 1e-9);
    json summary = {{"rank", rank_},
                    {"world_size", world_},
                    {"resumed_from", start},
                    {"steps", trained},
                    {"seconds", seconds},
                    {"samples_per_second", samples_per_second},
                    {"final_loss", last_loss_},
                    {"precision", nn::PrecisionName(options_.precision)}};
    if (rank_ == 0 && best_step_ >= 0)
      summary["best"] = {{"step", best_step_}, {"val_loss", best_val_}, {"kept", options_.keep}};
    const Status s =
        WriteFileAtomic(layout::RankSummaryFile(out_dir_, rank_), summary.dump(1) + "\n");
    if (!s.ok()) throw std::runtime_error(s.message());
    task_.Metric("final_loss", last_loss_);
    task_.Metric("samples_per_second", samples_per_second);
  }

  const Task& task_;
  const Options options_;
  const int rank_, world_;
  const std::string state_dir_, out_dir_, csv_, val_csv_, best_dir_;
  ModelHandle handle_;
  std::unique_ptr<plugin::Dataset> dataset_, val_dataset_;
  std::vector<torch::Tensor> params_;
  std::unique_ptr<torch::optim::AdamW> optimizer_;
  std::vector<torch::Tensor> ema_;  // rank 0, params.ema: the moving average of params_
  c10::intrusive_ptr<c10d::ProcessGroupGloo> group_;
  std::optional<nn::EpochOrder> order_;  // made with the training dataset
  std::ofstream log_;
  double last_loss_ = 0;
  double best_val_ = std::numeric_limits<double>::infinity();
  int64_t best_step_ = -1;
  std::chrono::steady_clock::time_point started_ = std::chrono::steady_clock::now();
  double seconds_before_ = 0;
};

void Train(const Task& task) { Trainer(task).Run(); }

const mp_stage_kind kKinds[] = {
    {"train", "data-parallel training of a model plugin (c10d Gloo), with checkpoints and resume",
     [](const mp_task_io* io, char* error, size_t size) {
       return plugin::RunStage(io, error, size, Train);
     }},
};

const mp_plugin kPlugin = {
    MOTIONPIPE_PLUGIN_ABI_VERSION, sizeof(mp_plugin), "train", "1.0.0", 1, kKinds, 0, nullptr};

}  // namespace

}  // namespace motionpipe::train

extern "C" __attribute__((visibility("default"))) const mp_plugin* motionpipe_plugin_v1(void) {
  return &motionpipe::train::kPlugin;
}
