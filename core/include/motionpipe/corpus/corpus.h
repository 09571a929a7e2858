// The embedded default dataset: a procedural motion corpus written in the real formats, so the real
// loaders read it and every stage can run without licensed data.
//
//   DIR/manifest.json                 what was generated, counts, options, sha256 of every file
//   (written last) DIR/clips/clips-NNNNN.npz         our clip layout: motions, captions, labelled
//   segments with ground-truth parts DIR/amass/<id>_poses.npz          AMASS-style npz per clip
//   (poses [T,156], trans, mocap_framerate, betas) DIR/babel/{train,val,test}.json   BABEL-style
//   annotations (seq_ann, frame_ann with proc_label, start_t, end_t)
//   DIR/motionfix/triplets-NNNNN.npz  MotionFix-style editing triplets in our converted layout,
//   with edit ranges DIR/motionfix/splits.json         triplet ids per split, as MotionFix ships
//   them DIR/texts/labels.json             every label and caption with its ground-truth body parts
//   (labeler evaluation)
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/corpus/edits.h"
#include "motionpipe/corpus/script.h"

namespace motionpipe::corpus {

// Thresholds every generated clip must pass; a clip that fails is resampled (counted as rejected).
struct PlausibilityGate {
  double max_skate_ratio = 0.08;
  double max_penetration = 0.01;  // metres
  double max_reach_error = 0.01;  // metres
  double max_joint_step = 0.9;    // metres per frame
  bool joint_limits = true;
  int max_attempts = 12;
};

struct CorpusOptions {
  std::string out_dir;
  uint64_t seed = 1;
  int64_t clips = 1000;
  int64_t triplets = -1;  // -1: as many as clips
  double fps = 30;
  int shard_size = 500;
  int threads = 0;             // OpenMP threads; 0 = the runtime's default
  bool triplet_joints = true;  // store FK joint positions with the triplets (as MotionFix does)
  bool write_amass = true;     // per-clip AMASS npz files (many small files)
  ScriptOptions script;
  PlausibilityGate gate;
  // The edits the triplets may make (ParseEditKinds); a script none of them applies to is drawn
  // again. Every kind, the default, gives the same triplets as before the option existed. Fewer
  // kinds are for experiments (issue 15: can an editor learn one kind of edit?), not a corpus.
  EditKindSet edit_kinds = kEveryEditKind;
  // The share of clip texts (each action's label and caption, drawn apart) that state the action's
  // manner when it is clearly off normal: tempo, repetitions, size (WithManner). 0, the default,
  // gives the same bytes as before the option existed; any value leaves every motion and triplet
  // as it is (the draws have a stream of their own), so only the texts differ. For an evaluator
  // that has to see speed, repetition and amplitude edits (issue 15).
  double manner_words = 0;
};

// An error unless `share` (CorpusOptions::manner_words) lies in [0, 1]; the stage's planning and
// the generator's option check share it.
Status CheckMannerWords(double share);

struct CorpusSummary {
  int64_t clips = 0, triplets = 0, frames = 0, triplet_frames = 0;
  int64_t rejected = 0;  // scripts resampled because a clip failed the gate
  double seconds = 0;
  std::map<std::string, int64_t> split_clips;
};

// Generates the corpus into options.out_dir (created when missing). Deterministic: the same options
// give byte-identical files, whatever the thread count. Equivalent to every GenerateCorpusShard
// followed by FinalizeCorpus.
Result<CorpusSummary> GenerateCorpus(const CorpusOptions& options);

// The distributed form (the pipeline's `corpus` stage): shard `index` of ShardCount(options) writes
// its clips (indices [index * shard_size, ...)), triplets, AMASS files and a shard.json of its
// annotations into `dir`; FinalizeCorpus then links every shard's files into options.out_dir and
// writes the merged BABEL/MotionFix/label files and the manifest. The result is byte-identical to
// GenerateCorpus whichever worker generated which shard.
int64_t ShardCount(const CorpusOptions& options);
Status GenerateCorpusShard(const CorpusOptions& options, int64_t index, const std::string& dir);
Result<CorpusSummary> FinalizeCorpus(const CorpusOptions& options,
                                     const std::vector<std::string>& shard_dirs);

// The split of item `index` (clips and triplets hash separately): train 80%, val 10%, test 10%.
std::string SplitOf(uint64_t seed, uint64_t stream, int64_t index);

}  // namespace motionpipe::corpus
