// What the stage kinds read from their inputs: input directories, triplet files, checkpoints, the
// spans table.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/formats/motionfix.h"
#include "motionpipe/motion/motion.h"
#include "motionpipe/sinc/spans.h"
#include "stage.h"

namespace motionpipe::stages {

std::vector<std::string> StringList(const json& v);

// The committed directories of `stage` (every input when empty): an input stage's, result first;
// or, for a path pattern (anything with a '/', e.g. an earlier job's "out/claims_edit-1/edit_mdt"),
// every match's result and task directories (a match that holds none is taken as it is).
std::vector<std::string> StageDirs(const TaskContext& ctx, const std::string& stage);

// Triplet files of `stage` (StageDirs; every input when empty), sorted: StageTripletFiles' rule (a
// stage with a result directory holding triplets, a corpus, is read from there only: its task
// directories hold the same triplets as shards).
std::vector<std::string> TripletFiles(const TaskContext& ctx, const std::string& stage = "");

// A checkpoint named by a stage parameter: an input stage's name, or a path pattern (anything with
// a '/', e.g. "out/train_mdt-*/mdt") whose newest checkpoint is taken: a scheduled evaluation of
// the latest training job.
std::string FindCheckpoint(const TaskContext& ctx, const std::string& stage);

// The generator of the checkpoint named by params.model (see FindCheckpoint), with `options`. With
// `model` given, a checkpoint of another model is refused by name before its weights are loaded.
Result<GeneratorPtr> OpenModel(const TaskContext& ctx, const PluginHost& plugins,
                               const json& options, std::string* checkpoint,
                               const std::string& model = "");

// The spans table of a `singles` stage: `stage` (an input's name or a path pattern, as StageDirs),
// or the first input that has one.
Result<sinc::SpanTable> InputSpans(const TaskContext& ctx, const std::string& stage = "");

// The spans a generation covers: split, kind (pairs | singles | all), limit; in table order.
std::vector<int64_t> SelectSpans(const sinc::SpanTable& table, const json& p);

std::string SpanText(const sinc::SpanTable& table, int64_t i);

}  // namespace motionpipe::stages
