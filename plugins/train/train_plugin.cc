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
//   127.0.0.1), store (tcp | file; default tcp), collective_timeout (seconds, default 120)
//
// Rank r of W takes every W-th example of each global batch, and the gradients are averaged over
// the ranks (all-reduce of one flattened buffer), so W ranks take the same step as one rank on the
// whole batch. Rank 0 writes the checkpoints (state_dir/ckpt-NNNNNNNN, then state_dir/latest) and,
// at the end, the trained model into its output: model/ (model.pt, model.json, extras),
// state_dict.pt (loadable by Python's torch.load) and losses.csv.
#include <omp.h>
#include <torch/torch.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numeric>
#include <random>
#include <sstream>
#include <thread>
#include <torch/csrc/distributed/c10d/FileStore.hpp>
#include <torch/csrc/distributed/c10d/ProcessGroupGloo.hpp>
#include <torch/csrc/distributed/c10d/TCPStore.hpp>

#include "../api/model.hpp"
#include "../api/plugin.hpp"
#include "../common/threads.h"
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
  std::string schedule = "cosine";
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
            {"min_lr", min_lr},
            {"clip_grad", clip_grad},
            {"checkpoint_every", checkpoint_every},
            {"seed", seed},
            {"validate_every", validate_every},
            {"val_batches", val_batches},
            {"keep", keep}};
  }
};

double LearningRate(const Options& o, int64_t step) {
  if (o.warmup > 0 && step < o.warmup)
    return o.lr * static_cast<double>(step + 1) / static_cast<double>(o.warmup);
  if (o.schedule == "constant") return o.lr;
  const double progress = static_cast<double>(step - o.warmup) /
                          static_cast<double>(std::max<int64_t>(1, o.steps - o.warmup));
  return o.min_lr +
         0.5 * (o.lr - o.min_lr) * (1 + std::cos(3.14159265358979323846 * std::min(1.0, progress)));
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
};

std::optional<Checkpoint> LatestCheckpoint(const std::string& state_dir) {
  auto text = ReadFile(state_dir + "/latest");
  if (!text.ok()) return std::nullopt;
  std::string name = *text;
  while (!name.empty() && (name.back() == '\n' || name.back() == ' ')) name.pop_back();
  const std::string dir = state_dir + "/" + name;
  auto meta = ReadFile(dir + "/trainer.json");
  if (!meta.ok()) return std::nullopt;
  return Checkpoint{json::parse(*meta).value("step", int64_t{0}), dir};
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

// The mean loss over `batches` fixed batches of the held-out split: the same examples and the same
// per-example draws (diffusion steps, noise, reparameterisation) at every validation, dropout off.
double Validate(plugin::Model& model, plugin::Dataset& val, const Options& options) {
  torch::NoGradGuard no_grad;
  model.Module().eval();
  double total = 0;
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
    total += model.Losses(batch, 0).at("loss").item<double>();
  }
  model.Module().train();
  return total / static_cast<double>(options.val_batches);
}

void Train(const Task& task) {
  const Options options = Options::FromTask(task);
  const int rank = task.spec.value("index", 0);
  const int world = std::max(1, task.spec.value("world_size", 1));
  const std::string state_dir = task.spec.value("state_dir", std::string());
  const std::string out_dir = task.output_dir();
  if (state_dir.empty())
    throw plugin::BadInput("the train stage needs a state_dir (a coordinator that knows gangs)");
  fs::create_directories(state_dir);
  fs::create_directories(out_dir);
  nn::SetTorchThreads(omp_get_max_threads());
  torch::manual_seed(options.seed);

  ModelHandle handle;
  handle.factory = task.Factory("model", options.model);
  if (!handle.factory)
    throw plugin::BadInput("no model plugin '" + options.model + "' is loaded on this worker");
  char error[2048] = {0};
  handle.model = static_cast<plugin::Model*>(
      handle.factory->create(options.config.dump().c_str(), error, sizeof error));
  if (!handle.model) throw plugin::BadInput(std::string("model '") + options.model + "': " + error);
  plugin::Model& model = *handle.model;

  plugin::DataContext data;
  data.config = options.data;
  for (const auto& input : task.spec["inputs"]) {
    if (!input.value("result_dir", std::string()).empty())
      data.input_dirs.push_back(input["result_dir"].get<std::string>());
    for (const auto& dir : input["dirs"]) data.input_dirs.push_back(dir.get<std::string>());
  }
  data.state_dir = state_dir;
  data.rank = rank;
  data.world_size = world;
  data.seed = options.seed;
  std::unique_ptr<plugin::Dataset> dataset;
  try {
    dataset = model.MakeDataset(data);
  } catch (const std::invalid_argument& e) {
    throw plugin::BadInput(e.what());
  }
  // The held-out split for the validation loss (rank 0 validates; the others do not wait for it).
  std::unique_ptr<plugin::Dataset> val_dataset;
  if (options.validate_every > 0 && rank == 0) {
    plugin::DataContext val = data;
    val.split = "val";
    try {
      val_dataset = model.MakeDataset(val);
    } catch (const std::invalid_argument& e) {
      throw plugin::BadInput(std::string("validate_every: the held-out split: ") + e.what());
    }
  }
  if (options.batch_size % world != 0) {
    throw plugin::BadInput("batch_size " + std::to_string(options.batch_size) +
                           " must be divisible by world_size " + std::to_string(world));
  }

  std::vector<torch::Tensor> params;
  for (auto& p : model.Module().parameters()) {
    if (p.requires_grad()) params.push_back(p);
  }
  torch::optim::AdamW optimizer(params, torch::optim::AdamWOptions(options.lr)
                                            .betas({options.beta1, options.beta2})
                                            .weight_decay(options.weight_decay));

  // Resume from the newest checkpoint of an earlier attempt of this gang.
  int64_t start = 0;
  const std::string csv = layout::LossesFile(state_dir), val_csv = layout::ValLossesFile(state_dir),
                    best_dir = state_dir + "/best";
  double best_val = std::numeric_limits<double>::infinity();
  int64_t best_step = -1;
  if (const auto latest = LatestCheckpoint(state_dir)) {
    LoadModule(model.Module(), layout::ModelWeightsFile(latest->dir));
    torch::load(optimizer, latest->dir + "/optimizer.pt");
    start = latest->step;
    task.Log(MP_LOG_INFO,
             "rank " + std::to_string(rank) + " resumes from step " + std::to_string(start));
    if (rank == 0) {
      TruncateCsv(csv, start);
      TruncateCsv(val_csv, start + 1);  // a validation row is logged at the step it follows
      // The best model so far, if it was validated before the resumed step.
      if (auto meta = ReadFile(best_dir + "/best.json"); meta.ok()) {
        const json best = json::parse(*meta);
        if (best.value("step", int64_t{-1}) <= start)
          best_val = best.value("val_loss", best_val), best_step = best.value("step", best_step);
      }
    }
  } else if (rank == 0) {
    for (const std::string& file : {csv, val_csv}) fs::remove(file);
    fs::remove_all(best_dir);
  }

  c10::intrusive_ptr<c10d::ProcessGroupGloo> group;
  if (world > 1) {
    const std::string rendezvous = task.spec.value("rendezvous", std::string());
    if (rendezvous.empty())
      throw plugin::BadInput(
          "world_size > 1 but no rendezvous: run this stage through a coordinator");
    auto store = OpenStore(options, rendezvous, rank, world, task);
    auto gloo = c10d::ProcessGroupGloo::Options::create();
    gloo->devices.push_back(c10d::ProcessGroupGloo::createDeviceForHostname(options.gloo_host));
    gloo->timeout = std::chrono::seconds(options.collective_timeout);
    group = c10::make_intrusive<c10d::ProcessGroupGloo>(store, rank, world, gloo);
    // Every rank starts from rank 0's parameters.
    for (auto& p : model.Module().parameters()) {
      std::vector<at::Tensor> t = {p.data()};
      group->broadcast(t)->wait();
    }
  }

  const int64_t n = dataset->size();
  const int64_t per_epoch = std::max<int64_t>(1, n / options.batch_size);
  const int64_t local = options.batch_size / world;
  std::vector<int64_t> order;
  int64_t order_epoch = -1;
  std::ofstream log;
  std::vector<std::string> columns;
  const auto started = std::chrono::steady_clock::now();
  double last_loss = 0;
  model.Module().train();
  for (int64_t step = start; step < options.steps; ++step) {
    if (task.cancelled()) throw std::runtime_error("cancelled at step " + std::to_string(step));
    const int64_t epoch = step / per_epoch;
    if (epoch != order_epoch) {
      order.resize(static_cast<size_t>(n));
      std::iota(order.begin(), order.end(), 0);
      std::mt19937_64 rng(MixSeed(options.seed, static_cast<uint64_t>(epoch)));
      std::shuffle(order.begin(), order.end(), rng);
      order_epoch = epoch;
    }
    // This rank's part of the global batch: every world-th example.
    std::vector<int64_t> indices;
    const int64_t base = (step % per_epoch) * options.batch_size;
    for (int64_t k = rank; k < options.batch_size; k += world)
      indices.push_back(order[static_cast<size_t>((base + k) % n)]);
    plugin::Batch batch = dataset->Get(indices, MixSeed(options.seed, static_cast<uint64_t>(step)));
    // Each example's own random seed (its place in the global batch), for models whose sampling
    // must not depend on how the batch was split over ranks.
    std::vector<int64_t> example_seeds;
    for (int64_t k = rank; k < options.batch_size; k += world) {
      example_seeds.push_back(static_cast<int64_t>(
          MixSeed(MixSeed(options.seed, static_cast<uint64_t>(step)), static_cast<uint64_t>(k)) >>
          1));
    }
    batch.tensors["example_seed"] = torch::tensor(example_seeds, torch::kInt64);
    torch::manual_seed(MixSeed(options.seed, static_cast<uint64_t>(step * world + rank)));
    auto losses = model.Losses(batch, step);
    const auto loss = losses.at("loss");
    if (!std::isfinite(loss.item<double>()))
      throw std::runtime_error("loss is not finite at step " + std::to_string(step));
    optimizer.zero_grad();
    loss.backward();

    // Average gradients and the logged losses over the ranks in one all-reduce.
    std::vector<torch::Tensor> flat;
    for (auto& p : params)
      flat.push_back(p.grad().defined() ? p.grad().reshape({-1}) : torch::zeros({p.numel()}));
    std::vector<std::string> names;
    std::vector<float> values;
    for (const auto& [name, value] : losses) {
      names.push_back(name);
      values.push_back(value.detach().item<float>());
    }
    flat.push_back(torch::tensor(values));
    auto buffer = torch::cat(flat);
    if (group) {
      std::vector<at::Tensor> t = {buffer};
      group->allreduce(t)->wait();
      buffer.div_(static_cast<double>(world));
    }
    int64_t offset = 0;
    for (auto& p : params) {
      if (p.grad().defined())
        p.mutable_grad().copy_(buffer.narrow(0, offset, p.numel()).view_as(p));
      offset += p.numel();
    }
    const auto averaged = buffer.narrow(0, offset, static_cast<int64_t>(values.size()));
    if (options.clip_grad > 0) torch::nn::utils::clip_grad_norm_(params, options.clip_grad);
    const double lr = LearningRate(options, step);
    for (auto& group_options : optimizer.param_groups())
      static_cast<torch::optim::AdamWOptions&>(group_options.options()).lr(lr);
    optimizer.step();

    last_loss = averaged[static_cast<int64_t>(std::find(names.begin(), names.end(), "loss") -
                                              names.begin())]
                    .item<double>();
    if (rank == 0) {
      if (!log.is_open()) {
        const bool fresh = !fs::exists(csv);
        log.open(csv, std::ios::app);
        columns = names;
        if (fresh) {
          log << "step,epoch,lr";
          for (const auto& c : columns) log << "," << c;
          log << "\n";
        }
      }
      log << step << "," << epoch << "," << lr;
      for (int64_t k = 0; k < static_cast<int64_t>(names.size()); ++k)
        log << "," << averaged[k].item<float>();
      log << "\n";
      if ((step + 1) % options.log_every == 0 || step + 1 == options.steps) {
        log.flush();
        task.Metric("loss", last_loss);
        task.Metric("step", static_cast<double>(step + 1));
        task.Metric("lr", lr);
      }
      if (val_dataset && ((step + 1) % options.validate_every == 0 || step + 1 == options.steps)) {
        const double val_loss = Validate(model, *val_dataset, options);
        const bool fresh = !fs::exists(val_csv);
        std::ofstream val_log(val_csv, std::ios::app);
        if (fresh) val_log << "step,val_loss\n";
        val_log << step << "," << val_loss << "\n";
        task.Metric("val_loss", val_loss);
        if (val_loss < best_val) {
          best_val = val_loss, best_step = step + 1;
          fs::remove_all(best_dir + ".tmp");
          WriteModelDir(model, options, best_step, best_dir + ".tmp");
          const Status s =
              WriteFileAtomic(best_dir + ".tmp/best.json",
                              json({{"step", best_step}, {"val_loss", best_val}}).dump() + "\n");
          if (!s.ok()) throw std::runtime_error(s.message());
          fs::remove_all(best_dir);
          fs::rename(best_dir + ".tmp", best_dir);
        }
      }
      if ((step + 1) % options.checkpoint_every == 0 && step + 1 < options.steps) {
        log.flush();
        const std::string name = "ckpt-" + std::to_string(100000000 + step + 1).substr(1);
        const std::string tmp = state_dir + "/" + name + ".tmp";
        fs::remove_all(tmp);
        fs::create_directories(tmp);
        SaveModule(model.Module(), layout::ModelWeightsFile(tmp));
        torch::save(optimizer, tmp + "/optimizer.pt");
        const Status s = WriteFileAtomic(
            tmp + "/trainer.json",
            json({{"step", step + 1}, {"epoch", epoch}, {"world_size", world}}).dump() + "\n");
        if (!s.ok()) throw std::runtime_error(s.message());
        fs::remove_all(state_dir + "/" + name);
        fs::rename(tmp, state_dir + "/" + name);
        const Status latest = WriteFileAtomic(state_dir + "/latest", name + "\n");
        if (!latest.ok()) throw std::runtime_error(latest.message());
        // Older checkpoints beyond keep_checkpoints go.
        std::vector<std::string> all;
        for (const auto& entry : fs::directory_iterator(state_dir)) {
          const std::string file = entry.path().filename().string();
          if (file.rfind("ckpt-", 0) == 0 && file.find(".tmp") == std::string::npos)
            all.push_back(file);
        }
        std::sort(all.begin(), all.end());
        for (size_t k = 0; k + static_cast<size_t>(options.keep_checkpoints) < all.size(); ++k)
          fs::remove_all(state_dir + "/" + all[k]);
      }
    }
  }
  if (log.is_open()) log.close();
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  if (rank == 0) {
    model.Module().eval();
    if (options.keep == "best" && best_step >= 0 && best_step < options.steps) {
      // The lowest validation loss: that model is the output (its weights, extras and step).
      LoadModule(model.Module(), layout::ModelWeightsFile(best_dir));
      WriteModelDir(model, options, best_step, layout::CheckpointDir(out_dir));
    } else {
      WriteModelDir(model, options, options.steps, layout::CheckpointDir(out_dir));
    }
    ExportStateDict(model.Module(), out_dir + "/state_dict.pt");
    for (const std::string& file : {csv, val_csv}) {
      if (fs::exists(file))
        fs::copy_file(file, out_dir + "/" + fs::path(file).filename().string(),
                      fs::copy_options::overwrite_existing);
    }
  }
  const int64_t trained = options.steps - start;
  json summary = {
      {"rank", rank},
      {"world_size", world},
      {"resumed_from", start},
      {"steps", trained},
      {"seconds", seconds},
      {"samples_per_second", static_cast<double>(trained * local) / std::max(seconds, 1e-9)},
      {"final_loss", last_loss}};
  if (rank == 0 && best_step >= 0)
    summary["best"] = {{"step", best_step}, {"val_loss", best_val}, {"kept", options.keep}};
  const Status s = WriteFileAtomic(layout::RankSummaryFile(out_dir, rank), summary.dump(1) + "\n");
  if (!s.ok()) throw std::runtime_error(s.message());
  task.Metric("final_loss", last_loss);
  task.Metric("samples_per_second", static_cast<double>(trained * local) / std::max(seconds, 1e-9));
}

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
