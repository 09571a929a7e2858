// The distributed engine's logic, in-process: pipeline specs, cron, the journal, the scheduler's
// failure classes under a fake clock, the wire protocol's guards and the plugin host.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <set>

#include "cron.h"
#include "executor.h"
#include "generators.h"
#include "journal.h"
#include "motionpipe/base/file.h"
#include "motionpipe/base/job_layout.h"
#include "motionpipe/net/protocol.h"
#include "motionpipe/net/security.h"
#include "pipeline.h"
#include "plugin_host.h"
#include "scheduler.h"
#include "test_util.h"

namespace motionpipe::coordinator {
namespace {

namespace fs = std::filesystem;

const KindRegistry& Kinds() {
  static const KindRegistry kinds = [] {
    KindRegistry k = KindRegistry::WithBuiltins();
    k.AddGeneric("sample.checksum");
    return k;
  }();
  return kinds;
}

constexpr char kPipeline[] = R"(
name: test
output_root: OUT
seed: 5
vars: {n: 4}
defaults: {max_attempts: 2, retry_backoff: 2s}
stages:
  write:
    kind: test.write
    params: {tasks: "${vars.n}"}
  check:
    kind: sample.checksum
    inputs: [write]
    timeout: 30s
)";

std::string PipelineIn(const std::string& root, const std::string& text = kPipeline) {
  std::string yaml = text;
  yaml.replace(yaml.find("OUT"), 3, root);
  return yaml;
}

// ---- pipeline
// ------------------------------------------------------------------------------------

TEST(Pipeline, ParsesPlansAndOrdersStages) {
  auto spec = ParsePipeline(PipelineIn("out"), {}, "p.yaml", Kinds());
  ASSERT_TRUE(spec.ok()) << spec.status().ToString();
  ASSERT_EQ(spec->stages.size(), 2u);
  EXPECT_EQ(spec->stages[0].name, "write");
  EXPECT_EQ(spec->stages[0].shards, 4);  // ${vars.n} kept its integer type
  EXPECT_EQ(spec->stages[0].max_attempts, 2);
  EXPECT_EQ(spec->stages[0].retry_backoff_seconds, 2.0);
  EXPECT_EQ(spec->stages[1].timeout_seconds, 30.0);
  EXPECT_EQ(spec->stages[1].inputs, std::vector<std::string>{"write"});
  EXPECT_EQ(spec->seed, 5u);
  EXPECT_EQ(spec->fingerprint.size(), 64u);
  // Declared out of order: the DAG decides.
  auto reordered =
      ParsePipeline("name: r\nstages:\n  b: {kind: noop, inputs: [a]}\n  a: {kind: noop}\n", {},
                    "r.yaml", Kinds());
  ASSERT_TRUE(reordered.ok());
  EXPECT_EQ(reordered->stages[0].name, "a");
  // The corpus planner shards by clip count and adds a reduce task.
  auto corpus = ParsePipeline(
      "name: c\nstages:\n  corpus: {kind: corpus, params: {clips: 1200, triplets: 100, shard_size: "
      "500}}\n",
      {}, "c.yaml", Kinds());
  ASSERT_TRUE(corpus.ok());
  EXPECT_EQ(corpus->stages[0].shards, 3);
  EXPECT_TRUE(corpus->stages[0].reduce);
  // An edit kind the corpus does not make is a planning error that names the stage and the kind.
  auto kinds = ParsePipeline(
      "name: c\nstages:\n  corpus: {kind: corpus, params: {clips: 10, edit_kinds: [side, "
      "mirror]}}\n",
      {}, "c.yaml", Kinds());
  ASSERT_FALSE(kinds.ok());
  EXPECT_NE(kinds.status().message().find("stages.corpus.params.edit_kinds: unknown edit kind "
                                          "'mirror'"),
            std::string::npos)
      << kinds.status().message();
  // So is a share of manner words outside [0, 1], or not a number.
  for (const char* bad : {"1.5", "-0.1", "half"}) {
    auto manner = ParsePipeline(std::string("name: c\nstages:\n  corpus: {kind: corpus, params: "
                                            "{clips: 10, manner_words: ") +
                                    bad + "}}\n",
                                {}, "c.yaml", Kinds());
    ASSERT_FALSE(manner.ok()) << bad;
    EXPECT_NE(
        manner.status().message().find("stages.corpus.params.manner_words: a share in [0, 1]"),
        std::string::npos)
        << manner.status().message();
  }
  EXPECT_TRUE(ParsePipeline("name: c\nstages:\n  corpus: {kind: corpus, params: {clips: 10, "
                            "manner_words: 0.5}}\n",
                            {}, "c.yaml", Kinds())
                  .ok());
}

// Long-running kinds get a 6 h lease unless the YAML sets one, even one equal to the 1 h default
// (a `timeout: 1h` used to be read as "not set").
TEST(Pipeline, AnExplicitTimeoutIsKeptByLongRunningKinds) {
  const std::string yaml =
      "name: t\nstages:\n  a: {kind: train, params: {model: m}}\n"
      "  b: {kind: train, timeout: 1h, params: {model: m}}\n";
  auto spec = ParsePipeline(yaml, {}, "t.yaml", Kinds());
  ASSERT_TRUE(spec.ok()) << spec.status().ToString();
  EXPECT_EQ(spec->stages[0].timeout_seconds, 6 * 3600.0);
  EXPECT_EQ(spec->stages[1].timeout_seconds, 3600.0);
  auto defaults = ParsePipeline(
      "name: t\ndefaults: {timeout: 2h}\nstages:\n  a: {kind: edit, inputs: [b]}\n  b: {kind: "
      "noop}\n",
      {}, "t.yaml", Kinds());
  ASSERT_TRUE(defaults.ok()) << defaults.status().ToString();
  EXPECT_EQ(defaults->stages[1].timeout_seconds, 2 * 3600.0);
}

// What the showcase shows (its clips, the clip's action text, the edit) is the pipeline's choice:
// the engine has no default texts or folder (issue 16).
TEST(Pipeline, TheShowcaseIsToldItsClipsAndTexts) {
  auto spec =
      ParsePipeline("name: s\nstages:\n  a: {kind: noop}\n  show: {kind: showcase, inputs: [a]}\n",
                    {}, "s.yaml", Kinds());
  ASSERT_FALSE(spec.ok());
  for (const char* key : {"clips", "clip_text", "edit_text"}) {
    EXPECT_NE(spec.status().message().find(std::string("stages.show.params.") + key + ": required"),
              std::string::npos)
        << spec.status().message();
  }
}

// Every shipped pipeline (configs/*.yaml: the demo, the claims runs, the evaluations; and the
// experiments the README's measurements name, configs/experiments/*.yaml) parses and plans as it
// stands, so a README command never meets a YAML error.
TEST(Pipeline, EveryShippedConfigParsesAndPlans) {
  KindRegistry kinds = KindRegistry::WithBuiltins();
  kinds.AddGeneric("labeler.train");  // the labelers plugin's stage kind (a plugin-declared kind
                                      // plans generically)
  std::map<std::string, int> count;
  for (const std::string dir : {"configs", "configs/experiments"}) {
    for (const auto& entry : fs::directory_iterator(motionpipe::testing::SourceDir() + "/" + dir)) {
      if (entry.path().extension() != ".yaml") continue;
      auto text = ReadPipelineFile(entry.path().string());
      ASSERT_TRUE(text.ok()) << text.status().ToString();
      auto spec = ParsePipeline(*text, {}, entry.path().string(), kinds);
      EXPECT_TRUE(spec.ok()) << spec.status().ToString();
      if (spec.ok()) {
        EXPECT_FALSE(spec->stages.empty()) << entry.path();
      }
      ++count[dir];
    }
  }
  EXPECT_GE(count["configs"], 10);
  EXPECT_GE(count["configs/experiments"], 30);
}

TEST(Pipeline, OverridesAndInterpolation) {
  auto spec = ParsePipeline(
      PipelineIn("out"),
      {"stages.write.params.tasks=9", "stages.check.timeout=5m", "seed=11", "vars.extra=[1, 2]"},
      "p.yaml", Kinds());
  ASSERT_TRUE(spec.ok()) << spec.status().ToString();
  EXPECT_EQ(spec->stages[0].shards, 9);
  EXPECT_EQ(spec->stages[1].timeout_seconds, 300.0);
  EXPECT_EQ(spec->seed, 11u);
  auto other = ParsePipeline(PipelineIn("out"), {"stages.write.params.tasks=3"}, "p.yaml", Kinds());
  EXPECT_NE(spec->fingerprint, other->fingerprint);
  auto partial = ParsePipeline(
      "name: x\noutput_root: runs/${vars.scale}\nvars: {scale: small}\nstages: {a: {kind: noop}}\n",
      {}, "x.yaml", Kinds());
  ASSERT_TRUE(partial.ok());
  EXPECT_EQ(partial->output_root, "runs/small");
  EXPECT_FALSE(ParsePipeline(PipelineIn("out"), {"novalue"}, "p.yaml", Kinds()).ok());
  EXPECT_FALSE(ParsePipeline(PipelineIn("out"), {"name.sub=1"}, "p.yaml", Kinds()).ok());
}

// A derived pipeline (`base:`) is a merge patch over its base, resolved when its file is read:
// vars and a stage's params merge, null drops a stage, a list replaces; bases chain; what is kept
// is self-contained. A file without a base reads as its own text (its fingerprint unchanged).
TEST(Pipeline, DerivedPipelineMergesOverItsBase) {
  const std::string dir = ::testing::TempDir() + "/derived_pipelines";
  fs::remove_all(dir);
  fs::create_directories(dir + "/experiments");
  const std::string base_text = R"(name: claims
seed: 3
vars: {steps: 100, option: false}
stages:
  data: {kind: noop}
  mdt: {kind: noop, inputs: [data], params: {steps: "${vars.steps}", option: "${vars.option}"}}
  tmed: {kind: noop, inputs: [data], params: {steps: "${vars.steps}"}}
  mdm: {kind: noop, inputs: [data]}
  report: {kind: noop, inputs: [mdt, tmed, mdm]}
)";
  ASSERT_TRUE(WriteFileAtomic(dir + "/claims.yaml", base_text).ok());
  ASSERT_TRUE(WriteFileAtomic(dir + "/experiments/cut.yaml",
                              "base: ../claims.yaml\nname: cut\nvars: {option: true}\n"
                              "stages:\n  mdm: null\n  report: {inputs: [mdt, tmed]}\n"
                              "  tmed: {params: {steps: 7}}\n")
                  .ok());
  ASSERT_TRUE(WriteFileAtomic(dir + "/experiments/cut2.yaml",
                              "base: cut.yaml\nname: cut2\nvars: {steps: 5}\n")
                  .ok());

  auto own = ReadPipelineFile(dir + "/claims.yaml");
  ASSERT_TRUE(own.ok()) << own.status().ToString();
  EXPECT_EQ(*own, base_text);

  auto text = ReadPipelineFile(dir + "/experiments/cut2.yaml");
  ASSERT_TRUE(text.ok()) << text.status().ToString();
  EXPECT_EQ(text->find("base"), std::string::npos) << *text;
  auto spec = ParsePipeline(*text, {}, "cut2.yaml", Kinds());
  ASSERT_TRUE(spec.ok()) << spec.status().ToString();
  EXPECT_EQ(spec->name, "cut2");
  EXPECT_EQ(spec->seed, 3u);  // from the base
  std::map<std::string, StageSpec> stages;
  for (const StageSpec& st : spec->stages) stages[st.name] = st;
  ASSERT_EQ(stages.size(), 4u);  // mdm dropped
  EXPECT_EQ(stages.count("mdm"), 0u);
  EXPECT_EQ(stages["report"].inputs, (std::vector<std::string>{"mdt", "tmed"}));
  EXPECT_EQ(stages["mdt"].params["steps"], 5);      // cut2's var through the base's stage
  EXPECT_EQ(stages["mdt"].params["option"], true);  // cut's var
  EXPECT_EQ(stages["tmed"].params["steps"], 7);     // cut's param beats any var
  EXPECT_EQ(stages["tmed"].kind, "noop");           // the rest of the base's stage kept

  // Problems name the file: a cycle, a missing base, a derived file without a name.
  const auto refusal = [&](const std::string& name, const std::string& yaml) {
    EXPECT_TRUE(WriteFileAtomic(dir + "/" + name, yaml).ok());
    auto read = ReadPipelineFile(dir + "/" + name);
    EXPECT_FALSE(read.ok()) << name;
    return read.ok() ? std::string() : read.status().message();
  };
  ASSERT_TRUE(WriteFileAtomic(dir + "/b.yaml", "base: a.yaml\nname: b\n").ok());
  const std::string cycle = refusal("a.yaml", "base: b.yaml\nname: a\n");
  EXPECT_NE(cycle.find("a cycle"), std::string::npos) << cycle;
  const std::string lost = refusal("lost.yaml", "base: nowhere.yaml\nname: lost\n");
  EXPECT_NE(lost.find("lost.yaml: base"), std::string::npos) << lost;
  EXPECT_NE(lost.find("nowhere.yaml"), std::string::npos) << lost;
  const std::string anon = refusal("anon.yaml", "base: claims.yaml\nvars: {steps: 1}\n");
  EXPECT_NE(anon.find("name: required"), std::string::npos) << anon;
  // Pipeline text (the journal's, a submission's) must come resolved.
  auto raw = ParsePipeline("base: claims.yaml\nname: x\nstages: {a: {kind: noop}}\n", {}, "x.yaml",
                           Kinds());
  ASSERT_FALSE(raw.ok());
  EXPECT_NE(raw.status().message().find("x.yaml: base:"), std::string::npos)
      << raw.status().message();
  fs::remove_all(dir);
}

// `targets:` keeps the named stages and what they need through their inputs, seeds and all.
TEST(Pipeline, TargetsKeepWhatTheyNeed) {
  const std::string yaml = R"(
name: part
stages:
  data: {kind: noop}
  judge: {kind: noop, inputs: [data]}
  mdt: {kind: noop, inputs: data, seeds: 2}
  mdm: {kind: noop, inputs: [data], seeds: 2}
  eval_mdt: {kind: noop, inputs: [judge, mdt], seeds: 2}
  eval_mdm: {kind: noop, inputs: [judge, mdm], seeds: 2}
  report: {kind: noop, inputs: [eval_mdt, eval_mdm]}
)";
  auto spec = ParsePipeline(yaml, {"targets=[eval_mdt]"}, "part.yaml", Kinds());
  ASSERT_TRUE(spec.ok()) << spec.status().ToString();
  std::set<std::string> names;
  for (const StageSpec& st : spec->stages) names.insert(st.name);
  EXPECT_EQ(names,
            (std::set<std::string>{"data", "judge", "mdt", "mdt-s2", "eval_mdt", "eval_mdt-s2"}));
  auto all = ParsePipeline(yaml, {}, "part.yaml", Kinds());
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->stages.size(), 11u);
  auto unknown = ParsePipeline(yaml, {"targets=[eval_mdt, nosuch]"}, "part.yaml", Kinds());
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.status().message().find("part.yaml: targets[1]: not a stage"),
            std::string::npos)
      << unknown.status().message();
  EXPECT_FALSE(ParsePipeline(yaml, {"targets=report"}, "part.yaml", Kinds()).ok());
}

TEST(Pipeline, SeedsReplicateStagesAndTheirChains) {
  const std::string yaml = R"(
name: seeds
seed: 7
stages:
  data: {kind: noop}
  mdt: {kind: noop, inputs: [data], seeds: 3, params: {tasks: 1}}
  edit: {kind: noop, inputs: [mdt, data], seeds: 3, params: {model: mdt, other: data, seed: 40}}
  report: {kind: noop, inputs: [edit]}
)";
  auto spec = ParsePipeline(yaml, {}, "s.yaml", Kinds());
  ASSERT_TRUE(spec.ok()) << spec.status().ToString();
  std::map<std::string, const StageSpec*> by_name;
  for (const StageSpec& s : spec->stages) by_name[s.name] = &s;
  ASSERT_EQ(by_name.size(), 8u);
  ASSERT_TRUE(by_name.count("mdt-s3") && by_name.count("edit-s2"));
  EXPECT_FALSE(by_name["mdt"]->params.contains("seed"));  // replicate 1 is the stage as written
  EXPECT_EQ(by_name["mdt-s2"]->params["seed"], 8);        // pipeline seed + 1
  EXPECT_EQ(by_name["mdt-s3"]->replicate, 3);
  EXPECT_EQ(by_name["edit-s2"]->inputs, (std::vector<std::string>{"mdt-s2", "data"}));
  EXPECT_EQ(by_name["edit-s2"]->params["model"],
            "mdt-s2");  // a param naming a seeded input follows it
  EXPECT_EQ(by_name["edit-s2"]->params["other"], "data");
  EXPECT_EQ(by_name["edit-s3"]->params["seed"], 42);  // its own seed + 2
  EXPECT_EQ(by_name["edit"]->params["seed"], 40);
  EXPECT_EQ(by_name["report"]->inputs, (std::vector<std::string>{"edit", "edit-s2", "edit-s3"}));
  EXPECT_EQ(spec->stages.back().name, "report");
  // Chains must agree on the count; the count must be sane.
  auto mismatch = ParsePipeline(
      "name: m\nstages:\n  a: {kind: noop, seeds: 2}\n  b: {kind: noop, inputs: [a], seeds: 3}\n",
      {}, "m.yaml", Kinds());
  ASSERT_FALSE(mismatch.ok());
  EXPECT_NE(
      mismatch.status().message().find("stages.b.seeds: 3 replicates, but its input 'a' has 2"),
      std::string::npos);
  auto zero =
      ParsePipeline("name: z\nstages:\n  a: {kind: noop, seeds: 0}\n", {}, "z.yaml", Kinds());
  ASSERT_FALSE(zero.ok());
  EXPECT_NE(zero.status().message().find("stages.a.seeds: must be an integer from 1 to 100"),
            std::string::npos);
  // A replicated stage's own seed must be a number (a quoted one used to be dropped silently for
  // replicates 2..N); a seed from a var keeps the var's type.
  auto quoted =
      ParsePipeline("name: q\nstages:\n  a: {kind: noop, seeds: 2, params: {seed: \"6\"}}\n", {},
                    "q.yaml", Kinds());
  ASSERT_FALSE(quoted.ok());
  EXPECT_NE(quoted.status().message().find("stages.a.params.seed: must be a non-negative integer"),
            std::string::npos)
      << quoted.status().ToString();
  auto from_var = ParsePipeline(
      "name: v\nseed: 1\nvars: {first: 6}\nstages:\n  a: {kind: noop, seeds: 3, params: {seed: "
      "\"${vars.first}\"}}\n",
      {"vars.first=11"}, "v.yaml", Kinds());
  ASSERT_TRUE(from_var.ok()) << from_var.status().ToString();
  EXPECT_EQ(from_var->stages[0].params["seed"], 11);
  EXPECT_EQ(from_var->stages[2].params["seed"], 13);
}

TEST(Pipeline, ScalePicksVarsThatOverridesStillBeat) {
  const std::string yaml = R"(
name: scaled
scale: small
scales: {small: {n: 2}, big: {n: 6, m: 3}}
vars: {n: 1, m: 1}
stages:
  a: {kind: noop, params: {tasks: "${vars.n}"}}
  b: {kind: noop, params: {tasks: "${vars.m}"}}
)";
  auto small = ParsePipeline(yaml, {}, "s.yaml", Kinds());
  ASSERT_TRUE(small.ok()) << small.status().ToString();
  EXPECT_EQ(small->stages[0].shards, 2);
  EXPECT_EQ(small->stages[1].shards, 1);
  auto big = ParsePipeline(yaml, {"scale=big", "vars.m=4"}, "s.yaml", Kinds());
  ASSERT_TRUE(big.ok()) << big.status().ToString();
  EXPECT_EQ(big->stages[0].shards, 6);
  EXPECT_EQ(big->stages[1].shards, 4);  // the command line beats the scale
  auto unknown = ParsePipeline(yaml, {"scale=huge"}, "s.yaml", Kinds());
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(
      unknown.status().message().find("scale: must name one of scales (small, big), got \"huge\""),
      std::string::npos)
      << unknown.status().message();
}

TEST(Pipeline, EveryProblemIsReportedWithItsYamlPath) {
  const std::string bad = R"(
name: bad
colour: blue
stages:
  a: {kind: noop, retries: 3}
  b: {kind: nosuchkind}
  c: {kind: noop, inputs: [a, missing]}
  d: {kind: noop, timeout: soon, params: {tasks: 0}}
  e: {kind: noop, inputs: [f]}
  f: {kind: noop, inputs: [e]}
  g: {kind: noop, params: {tasks: "${vars.nope}"}}
)";
  auto spec = ParsePipeline(bad, {}, "bad.yaml", Kinds());
  ASSERT_FALSE(spec.ok());
  const std::string& m = spec.status().message();
  for (const char* expected :
       {"bad.yaml: colour: unknown key", "stages.a.retries: unknown key",
        "stages.b.kind: unknown kind 'nosuchkind'", "stages.c.inputs[1]: unknown stage 'missing'",
        "stages.d.timeout: must be a duration", "stages.d.params.tasks: must be an integer >= 1",
        "stages.g.params.tasks: unknown reference ${vars.nope}"}) {
    EXPECT_NE(m.find(expected), std::string::npos) << expected << "\n" << m;
  }
  auto cycle = ParsePipeline(
      "name: c\nstages:\n  e: {kind: noop, inputs: [f]}\n  f: {kind: noop, inputs: [e]}\n", {},
      "c.yaml", Kinds());
  ASSERT_FALSE(cycle.ok());
  EXPECT_NE(cycle.status().message().find("cycle among e, f"), std::string::npos);
  auto yaml = ParsePipeline("name: [unclosed\n", {}, "y.yaml", Kinds());
  ASSERT_FALSE(yaml.ok());
  EXPECT_NE(yaml.status().message().find("y.yaml:"), std::string::npos);
  auto cron = ParsePipeline("name: c\nschedule: '61 * * * *'\nstages: {a: {kind: noop}}\n", {},
                            "c.yaml", Kinds());
  ASSERT_FALSE(cron.ok());
  EXPECT_NE(cron.status().message().find("schedule: cron"), std::string::npos);
}

// Issue 17: a 600-byte alias bomb took 2.4 GB and killed a coordinator through `submit`, and so did
// a valid pipeline with `shards: 1000000000`. Both are errors naming the file.
TEST(Pipeline, AliasBombsAndBillionsOfTasksAreRejected) {
  std::string bomb =
      "name: bomb\nstages: {a: {kind: noop}}\nx0: &x0 [lol, lol, lol, lol, lol, lol, lol, lol, "
      "lol, lol]\n";
  for (int k = 1; k <= 9; ++k) {
    const std::string prev = "*x" + std::to_string(k - 1);
    bomb += "x" + std::to_string(k) + ": &x" + std::to_string(k) + " [" + prev;
    for (int r = 1; r < 10; ++r) bomb += ", " + prev;
    bomb += "]\n";
  }
  auto spec = ParsePipeline(bomb, {}, "bomb.yaml", Kinds());
  ASSERT_FALSE(spec.ok());
  EXPECT_NE(spec.status().message().find("bomb.yaml: the document expands to more than"),
            std::string::npos)
      << spec.status().message();
  auto override_bomb =
      ParsePipeline("name: o\nstages: {a: {kind: noop}}\n",
                    {"vars.x=" + bomb.substr(bomb.find("x0:"))}, "o.yaml", Kinds());
  EXPECT_FALSE(override_bomb.ok());

  auto shards = ParsePipeline("name: s\nstages: {a: {kind: noop, shards: 1000000000}}\n", {},
                              "s.yaml", Kinds());
  ASSERT_FALSE(shards.ok());
  EXPECT_NE(shards.status().message().find("s.yaml: the pipeline plans 1000000000 tasks (stage a: "
                                           "1000000000); a job holds at most 1000000"),
            std::string::npos)
      << shards.status().message();
  // Many legitimate tasks still plan.
  EXPECT_TRUE(
      ParsePipeline("name: s\nstages: {a: {kind: noop, shards: 200000}}\n", {}, "s.yaml", Kinds())
          .ok());
}

TEST(Pipeline, Durations) {
  double s = 0;
  EXPECT_TRUE(ParseDuration("90", &s));
  EXPECT_EQ(s, 90);
  EXPECT_TRUE(ParseDuration("500ms", &s));
  EXPECT_EQ(s, 0.5);
  EXPECT_TRUE(ParseDuration("2h", &s));
  EXPECT_EQ(s, 7200);
  EXPECT_FALSE(ParseDuration("two minutes", &s));
}

// ---- cron
// ----------------------------------------------------------------------------------------

int64_t Unix(int year, int month, int day, int hour, int minute) {
  std::tm tm{};
  tm.tm_year = year - 1900;
  tm.tm_mon = month - 1;
  tm.tm_mday = day;
  tm.tm_hour = hour;
  tm.tm_min = minute;
  return static_cast<int64_t>(timegm(&tm));
}

TEST(Cron, NextFireTimes) {
  const int64_t t0 = Unix(2026, 11, 21, 10, 7);  // a Saturday
  EXPECT_EQ(NextFireTime(*ParseCron("*/5 * * * *"), t0), Unix(2026, 11, 21, 10, 10));
  EXPECT_EQ(NextFireTime(*ParseCron("0 3 * * *"), t0), Unix(2026, 11, 22, 3, 0));
  EXPECT_EQ(NextFireTime(*ParseCron("@daily"), t0), Unix(2026, 11, 22, 0, 0));
  EXPECT_EQ(NextFireTime(*ParseCron("30 9 * * 1-5"), t0),
            Unix(2026, 11, 23, 9, 30));  // next Monday
  EXPECT_EQ(NextFireTime(*ParseCron("0 0 1 1 *"), t0), Unix(2027, 1, 1, 0, 0));
  // Day-of-month and day-of-week both restricted: either matches (Vixie cron).
  EXPECT_EQ(NextFireTime(*ParseCron("0 12 25 * 0"), t0),
            Unix(2026, 11, 22, 12, 0));  // Sunday comes first
  EXPECT_EQ(NextFireTime(*ParseCron("0 0 * * 7"), t0),
            Unix(2026, 11, 22, 0, 0));                        // 7 is Sunday too
  EXPECT_EQ(NextFireTime(*ParseCron("0 0 31 2 *"), t0), -1);  // never
  EXPECT_EQ(NextFireTime(*ParseCron("7 10 21 11 *"), t0),
            Unix(2027, 11, 21, 10, 7));  // strictly after
}

TEST(Cron, RejectsMalformedSpecs) {
  for (const char* bad : {"* * * *", "60 * * * *", "* 24 * * *", "* * 0 * *", "* * * 13 *",
                          "*/0 * * * *", "a * * * *", "5-1 * * * *"}) {
    EXPECT_FALSE(ParseCron(bad).ok()) << bad;
  }
}

// ---- journal
// -------------------------------------------------------------------------------------

TEST(Journal, JobsTasksOutputsAndSchedulesSurviveReopening) {
  const std::string path = ::testing::TempDir() + "/journal_test.sqlite";
  fs::remove(path);
  {
    auto journal = Journal::Open(path);
    ASSERT_TRUE(journal.ok()) << journal.status().ToString();
    StoredJob job;
    job.name = "j";
    job.pipeline = "{}";
    job.fingerprint = "abc";
    job.state = "running";
    job.output_dir = "/tmp/x";
    for (int t = 0; t < 3; ++t) {
      StoredTask task;
      task.stage = "s";
      task.index = t;
      job.tasks.push_back(task);
    }
    auto id = (*journal)->CreateJob(job);
    ASSERT_TRUE(id.ok());
    (*journal)->UpdateTask(*id, "s", 1, TaskState::kCommitted, 1, 2, "");
    (*journal)->AddOutputs(*id, "s", 1, {{"out.txt", "deadbeef", 10}});
    EXPECT_EQ((*journal)->buffered(), 2u);
    ASSERT_TRUE((*journal)->Flush().ok());
    (*journal)->UpdateTask(*id, "s", 2, TaskState::kCommitted, 0, 0,
                           "");  // never flushed: lost with the process
    ASSERT_TRUE((*journal)->AddSchedule({0, "nightly", "{}", "0 3 * * *", 12345}).ok());
  }
  auto journal = Journal::Open(path);
  ASSERT_TRUE(journal.ok());
  auto jobs = (*journal)->LoadUnfinished();
  ASSERT_TRUE(jobs.ok());
  ASSERT_EQ(jobs->size(), 1u);
  const StoredJob& job = jobs->front();
  EXPECT_EQ(job.fingerprint, "abc");
  ASSERT_EQ(job.tasks.size(), 3u);
  EXPECT_EQ(job.tasks[1].state, TaskState::kCommitted);
  EXPECT_EQ(job.tasks[1].errors, 1);
  EXPECT_EQ(job.tasks[1].lost, 2);
  ASSERT_EQ(job.tasks[1].outputs.size(), 1u);
  EXPECT_EQ(job.tasks[1].outputs[0].sha256, "deadbeef");
  EXPECT_EQ(job.tasks[2].state, TaskState::kPending);
  auto schedules = (*journal)->LoadSchedules();
  ASSERT_EQ(schedules->size(), 1u);
  EXPECT_EQ(schedules->front().next_fire, 12345);
  (*journal)->UpdateJob(job.id, "succeeded", 1.0, "");
  ASSERT_TRUE((*journal)->Flush().ok());
  EXPECT_TRUE((*journal)->LoadUnfinished()->empty());
  EXPECT_FALSE(Journal::Open("/proc/no/such/dir/journal.sqlite").ok());
}

// ---- scheduler
// -----------------------------------------------------------------------------------

class SchedulerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = ::testing::TempDir() + "/sched_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name();
    fs::remove_all(root_);
    fs::create_directories(root_);
    journal_path_ = root_ + "/journal.sqlite";
    Reopen();
  }
  void Reopen() {
    scheduler_.reset();
    journal_.reset();
    journal_ = std::move(Journal::Open(journal_path_).value());
    scheduler_ =
        std::make_unique<Scheduler>(journal_.get(), &clock_, Kinds(), SchedulerOptions{1.0, 3});
  }
  wire::Ready ReadyFor(const std::string& name, int credit,
                       std::vector<std::string> kinds = {"test.write", "sample.checksum", "noop"}) {
    wire::Ready ready;
    ready.set_worker_id(name);
    ready.set_credit(credit);
    for (const auto& k : kinds) ready.add_kinds(k);
    return ready;
  }
  std::vector<wire::Assign> Assigned(const std::string& identity) {
    std::vector<wire::Assign> out;
    for (auto& o : scheduler_->TakeOutgoing()) {
      if (o.assign && o.identity == identity) out.push_back(*o.assign);
    }
    return out;
  }
  // A worker's OK result, with a real output file in the staging directory.
  wire::TaskResult Ok(const wire::Assign& assign) {
    fs::create_directories(assign.task().output_dir());
    std::ofstream(assign.task().output_dir() + "/out.txt") << "task " << assign.task().index();
    wire::TaskResult r;
    r.set_attempt_id(assign.attempt_id());
    r.set_outcome(wire::TaskResult::OK);
    auto* out = r.add_outputs();
    out->set_path("out.txt");
    out->set_sha256("x");
    out->set_bytes(6);
    return r;
  }
  wire::TaskResult Outcome(const wire::Assign& assign, wire::TaskResult::Outcome outcome,
                           const std::string& message) {
    wire::TaskResult r;
    r.set_attempt_id(assign.attempt_id());
    r.set_outcome(outcome);
    r.set_message(message);
    return r;
  }
  wire::StageStatus StageOf(int64_t job, const std::string& stage) {
    const std::vector<wire::JobStatus> jobs = scheduler_->JobStatuses(job);
    for (const auto& s : jobs.at(0).stages()) {
      if (s.name() == stage) return s;
    }
    return {};
  }

  FakeClock clock_{1.8e9};
  std::string root_, journal_path_;
  std::unique_ptr<Journal> journal_;
  std::unique_ptr<Scheduler> scheduler_;
};

TEST_F(SchedulerTest, DispatchByCreditAndKindCommitAndFinish) {
  auto job = scheduler_->Submit(PipelineIn(root_), {}, "p.yaml");
  ASSERT_TRUE(job.ok()) << job.status().ToString();
  scheduler_->OnReady("w1", ReadyFor("w1", 3));
  scheduler_->OnReady("noop-only", ReadyFor("noop-only", 5, {"noop"}));
  scheduler_->Dispatch();
  auto first = Assigned("w1");
  ASSERT_EQ(first.size(), 3u);                 // credit 3
  EXPECT_TRUE(Assigned("noop-only").empty());  // cannot run test.write
  EXPECT_EQ(first[0].task().stage(), "write");
  for (const auto& a : first) scheduler_->OnResult("w1", Ok(a));
  scheduler_->Dispatch();
  auto second = Assigned("w1");
  ASSERT_EQ(second.size(), 1u);  // the 4th write; 'check' waits for its input stage
  scheduler_->OnResult("w1", Ok(second[0]));
  scheduler_->Dispatch();
  auto check = Assigned("w1");
  ASSERT_EQ(check.size(), 1u);
  EXPECT_EQ(check[0].task().stage(), "check");
  ASSERT_EQ(check[0].task().inputs_size(), 1);
  EXPECT_EQ(check[0].task().inputs(0).dirs_size(), 4);
  EXPECT_TRUE(fs::exists(check[0].task().inputs(0).dirs(2) + "/out.txt"));  // committed into place
  scheduler_->OnResult("w1", Ok(check[0]));
  EXPECT_EQ(scheduler_->JobState(*job), "succeeded");
  EXPECT_EQ(scheduler_->counters().committed, 5);
}

TEST_F(SchedulerTest, GangsStartTogetherOnDistinctWorkersAndRestartTogether) {
  const std::string yaml = "name: g\noutput_root: " + root_ +
                           "\nstages:\n  t: {kind: noop, world_size: 2, retry_backoff: 1s}\n";
  auto job = scheduler_->Submit(yaml, {}, "g.yaml");
  ASSERT_TRUE(job.ok()) << job.status().ToString();
  auto take = [&] {
    std::map<std::string, std::vector<wire::Assign>> assigns;
    std::map<std::string, std::vector<int64_t>> cancels;
    for (auto& o : scheduler_->TakeOutgoing()) {
      if (o.assign) assigns[o.identity].push_back(*o.assign);
      if (o.cancel) cancels[o.identity].push_back(o.cancel->attempt_id());
    }
    return std::make_pair(assigns, cancels);
  };
  scheduler_->OnReady("w1", ReadyFor("w1", 4));
  scheduler_->Dispatch();
  EXPECT_TRUE(take().first.empty());  // one worker cannot hold a gang of two, even with credit 4
  scheduler_->OnReady("w2", ReadyFor("w2", 1));
  scheduler_->Dispatch();
  auto [assigns, cancels] = take();
  ASSERT_EQ(assigns["w1"].size(), 1u);
  ASSERT_EQ(assigns["w2"].size(), 1u);
  const wire::Assign r0 =
      assigns["w1"][0].task().index() == 0 ? assigns["w1"][0] : assigns["w2"][0];
  const wire::Assign r1 =
      assigns["w1"][0].task().index() == 1 ? assigns["w1"][0] : assigns["w2"][0];
  EXPECT_EQ(r0.task().world_size(), 2);
  EXPECT_EQ(r0.task().rendezvous(), r1.task().rendezvous());
  EXPECT_FALSE(r0.task().rendezvous().empty());
  EXPECT_EQ(fs::path(r0.task().state_dir()).lexically_normal(),
            fs::path(root_ + "/g-1/t/state").lexically_normal());
  // Rank 1 fails: rank 0 is cancelled, and both start again together after the backoff.
  scheduler_->OnResult(assigns["w1"][0].task().index() == 1 ? "w1" : "w2",
                       Outcome(r1, wire::TaskResult::ERROR, "boom"));
  auto [none, stopped] = take();
  EXPECT_TRUE(none.empty());
  EXPECT_EQ(stopped.size(), 1u);
  scheduler_->Dispatch();
  EXPECT_TRUE(take().first.empty());  // rank 1 is still in its backoff
  clock_.Advance(2);
  scheduler_->Tick();
  auto [again, unused] = take();
  ASSERT_EQ(again["w1"].size() + again["w2"].size(), 2u);
  const wire::Assign a = again["w1"][0], b = again["w2"][0];
  EXPECT_EQ(a.task().rendezvous(), b.task().rendezvous());
  EXPECT_NE(a.task().rendezvous(), r0.task().rendezvous());  // a new rendezvous for the new gang
  // A lost worker stops the gang without using the retry budget.
  scheduler_->OnDisconnect("w2");
  auto [after_loss, cancel_after_loss] = take();
  EXPECT_EQ(cancel_after_loss["w1"].size(), 1u);
  scheduler_->OnReady("w3", ReadyFor("w3", 1));
  scheduler_->Dispatch();
  auto [third, unused2] = take();
  ASSERT_EQ(third["w1"].size(), 1u);
  ASSERT_EQ(third["w3"].size(), 1u);
  scheduler_->OnResult("w1", Ok(third["w1"][0]));
  scheduler_->OnResult("w3", Ok(third["w3"][0]));
  EXPECT_EQ(scheduler_->JobState(*job), "succeeded");
}

TEST_F(SchedulerTest, LostWorkerRequeuesWithoutUsingTheRetryBudget) {
  auto job = scheduler_->Submit(PipelineIn(root_), {}, "p.yaml");
  scheduler_->OnReady("w1", ReadyFor("w1", 1));
  scheduler_->Dispatch();
  ASSERT_EQ(Assigned("w1").size(), 1u);
  clock_.Advance(3.5);  // > liveness * heartbeat without a word
  scheduler_->Tick();
  EXPECT_EQ(scheduler_->TakeLostWorkers(), std::vector<std::string>{"w1"});
  EXPECT_EQ(scheduler_->live_workers(), 0u);
  EXPECT_EQ(StageOf(*job, "write").failed(), 0);
  scheduler_->OnReady("w2", ReadyFor("w2", 4));
  scheduler_->Dispatch();
  auto again = Assigned("w2");
  ASSERT_EQ(again.size(), 4u);  // the lost task is among them, with no backoff
  int retried = 0;
  for (const auto& x : again) retried += x.task().attempt() == 1;  // one loss, no errors
  EXPECT_EQ(retried, 1);
  for (const auto& a : again) scheduler_->OnResult("w2", Ok(a));
  EXPECT_EQ(StageOf(*job, "write").committed(), 4);
  EXPECT_EQ(scheduler_->counters().errors, 0);
  EXPECT_EQ(scheduler_->counters().lost, 1);
}

TEST_F(SchedulerTest, PoisonTaskIsQuarantinedAndReported) {
  auto job = scheduler_->Submit(
      "name: p\noutput_root: " + root_ + "\nstages: {w: {kind: test.write, poison_threshold: 3}}\n",
      {}, "p.yaml");
  for (int k = 0; k < 3; ++k) {
    const std::string w = "w" + std::to_string(k);
    scheduler_->OnReady(w, ReadyFor(w, 1));
    scheduler_->Dispatch();
    ASSERT_EQ(Assigned(w).size(), 1u) << k;
    scheduler_->OnDisconnect(w);  // the task took the worker down with it
  }
  EXPECT_EQ(scheduler_->JobState(*job), "failed");
  const auto stage = StageOf(*job, "w");
  EXPECT_EQ(stage.quarantined(), 1);
  ASSERT_EQ(stage.failures_size(), 1);
  EXPECT_NE(stage.failures(0).find("quarantined"), std::string::npos);
  EXPECT_NE(stage.failures(0).find("3 workers died (poison)"), std::string::npos);
}

TEST_F(SchedulerTest, ErrorsBackOffThenFailAfterMaxAttempts) {
  auto job = scheduler_->Submit(PipelineIn(root_), {"stages.write.params.tasks=1"},
                                "p.yaml");  // max_attempts 2, backoff 2s
  scheduler_->OnReady("w1", ReadyFor("w1", 5));
  scheduler_->Dispatch();
  auto a = Assigned("w1");
  ASSERT_EQ(a.size(), 1u);
  scheduler_->OnResult("w1", Outcome(a[0], wire::TaskResult::ERROR, "disk full"));
  scheduler_->Dispatch();
  EXPECT_TRUE(Assigned("w1").empty());  // backing off
  clock_.Advance(1.0);
  scheduler_->Tick();
  EXPECT_TRUE(Assigned("w1").empty());
  clock_.Advance(1.5);
  scheduler_->OnSeen("w1");
  scheduler_->Tick();
  auto b = Assigned("w1");
  ASSERT_EQ(b.size(), 1u);
  EXPECT_EQ(b[0].task().attempt(), 1);
  scheduler_->OnResult("w1", Outcome(b[0], wire::TaskResult::ERROR, "disk full again"));
  EXPECT_EQ(scheduler_->JobState(*job), "failed");
  EXPECT_NE(StageOf(*job, "write").failures(0).find("failed after 2 attempt(s): disk full again"),
            std::string::npos);
}

TEST_F(SchedulerTest, BadInputFailsAtOnce) {
  auto job = scheduler_->Submit(PipelineIn(root_), {}, "p.yaml");
  scheduler_->OnReady("w1", ReadyFor("w1", 1));
  scheduler_->Dispatch();
  auto a = Assigned("w1");
  scheduler_->OnResult("w1",
                       Outcome(a[0], wire::TaskResult::BAD_INPUT, "clip 3 has NaN rotations"));
  EXPECT_EQ(scheduler_->JobState(*job), "failed");
  EXPECT_NE(StageOf(*job, "write").failures(0).find("rejected its input: clip 3 has NaN rotations"),
            std::string::npos);
  EXPECT_EQ(scheduler_->counters().errors, 1);
}

TEST_F(SchedulerTest, SlowWorkerLeaseExpiresTheTaskMovesOnFirstCommitWins) {
  auto job = scheduler_->Submit(
      PipelineIn(root_), {"stages.write.params.tasks=1", "stages.write.timeout=10s"}, "p.yaml");
  scheduler_->OnReady("slow", ReadyFor("slow", 1));
  scheduler_->Dispatch();
  auto slow = Assigned("slow");
  ASSERT_EQ(slow.size(), 1u);
  for (int k = 0; k < 11; ++k) {  // the slow worker heartbeats, but its task overstays the lease
    clock_.Advance(1);
    scheduler_->OnSeen("slow");
    scheduler_->Tick();
  }
  auto cancels = scheduler_->TakeOutgoing();
  ASSERT_EQ(cancels.size(), 1u);
  ASSERT_TRUE(cancels[0].cancel.has_value());
  clock_.Advance(2.0);  // backoff after the lease error
  scheduler_->OnSeen("slow");
  scheduler_->OnReady("fast", ReadyFor("fast", 1));
  scheduler_->Tick();
  auto fast = Assigned("fast");
  ASSERT_EQ(fast.size(), 1u);
  scheduler_->OnResult("fast", Ok(fast[0]));
  EXPECT_EQ(StageOf(*job, "write").committed(), 1);
  // The slow attempt finishes afterwards: a duplicate, discarded; one output stays.
  scheduler_->OnResult("slow", Ok(slow[0]));
  EXPECT_EQ(scheduler_->counters().duplicates, 1);
  EXPECT_FALSE(fs::exists(slow[0].task().output_dir()));
  EXPECT_TRUE(fs::exists(fs::path(slow[0].task().output_dir()).parent_path().parent_path() /
                         "task-00000/out.txt"));
  EXPECT_EQ(scheduler_->counters().lease_expired, 1);
}

TEST_F(SchedulerTest, HandedBackTasksReturnWithoutPenalty) {
  auto job = scheduler_->Submit(PipelineIn(root_), {}, "p.yaml");
  scheduler_->OnReady("w1", ReadyFor("w1", 2));
  scheduler_->Dispatch();
  auto a = Assigned("w1");
  scheduler_->OnDrain("w1");
  for (const auto& x : a)
    scheduler_->OnResult("w1", Outcome(x, wire::TaskResult::HANDED_BACK, "preempted"));
  scheduler_->Dispatch();
  EXPECT_TRUE(Assigned("w1").empty());  // a draining worker gets nothing new
  scheduler_->OnReady("w2", ReadyFor("w2", 4));
  scheduler_->Dispatch();
  auto b = Assigned("w2");
  ASSERT_EQ(b.size(), 4u);
  EXPECT_EQ(b[0].task().attempt(), 0);
  EXPECT_EQ(scheduler_->counters().handed_back, 2);
  (void)job;
}

// Issue 17: with credit 2 a second long training sat queued behind a first on one worker while
// another worker idled. A task queued on a busy worker for reclaim_after_seconds is asked back
// (Cancel with only_if_queued) for an idle worker, and the idle worker gets it, not its old holder.
TEST_F(SchedulerTest, ATaskQueuedOnABusyWorkerIsReclaimedForAnIdleOne) {
  auto job = scheduler_->Submit(PipelineIn(root_), {}, "p.yaml");
  ASSERT_TRUE(job.ok());
  scheduler_->OnReady("w1", ReadyFor("w1", 4));
  scheduler_->Dispatch();
  const auto a = Assigned("w1");
  ASSERT_EQ(a.size(), 4u);  // every write, one running and three queued
  scheduler_->OnReady("w2", ReadyFor("w2", 2));
  const auto reclaims = [&] {
    std::vector<wire::Cancel> out;
    for (auto& o : scheduler_->TakeOutgoing()) {
      if (o.cancel) {
        EXPECT_EQ(o.identity, "w1");
        out.push_back(*o.cancel);
      }
    }
    return out;
  };
  scheduler_->Dispatch();
  EXPECT_TRUE(reclaims().empty());  // queued for less than a second: prefetching still pays
  clock_.Advance(2);
  scheduler_->Dispatch();
  auto asked = reclaims();
  ASSERT_EQ(asked.size(), 1u);  // one for the one idle worker
  EXPECT_TRUE(asked[0].only_if_queued());
  EXPECT_EQ(asked[0].attempt_id(), a[3].attempt_id());  // the newest, never the running one
  scheduler_->Dispatch();
  EXPECT_TRUE(reclaims().empty());  // asked once, not again while the answer is on its way
  scheduler_->OnResult("w1", Outcome(a[3], wire::TaskResult::HANDED_BACK, "reclaimed"));
  scheduler_->Dispatch();
  const auto b = Assigned("w2");
  ASSERT_EQ(b.size(), 1u);
  EXPECT_EQ(b[0].task().index(), a[3].task().index());
  EXPECT_EQ(b[0].task().attempt(), 0);  // no retry budget used
  // w1 finishes its running task; w2 is busy, so nothing more is reclaimed for it.
  scheduler_->OnResult("w1", Ok(a[0]));
  clock_.Advance(2);
  scheduler_->Dispatch();
  EXPECT_TRUE(reclaims().empty());
  EXPECT_EQ(StageOf(*job, "write").committed(), 1);
}

// Job ids are a journal's own: a second journal over the same output root numbers its first job 1
// as well. Its job must not write into (or resume trainers from) the first journal's directory.
TEST_F(SchedulerTest, ANewJobRefusesAnotherJournalsDirectory) {
  auto first = scheduler_->Submit(PipelineIn(root_), {}, "p.yaml");
  ASSERT_TRUE(first.ok()) << first.status().ToString();
  const std::string dir = root_ + "/test-" + std::to_string(*first);
  ASSERT_TRUE(fs::is_directory(dir));
  std::ofstream(dir + "/kept.txt") << "an earlier job's output";
  journal_path_ = root_ + "/other-journal.sqlite";
  Reopen();
  auto second = scheduler_->Submit(PipelineIn(root_), {}, "p.yaml");
  ASSERT_FALSE(second.ok());
  EXPECT_NE(second.status().message().find("/test-1 already holds the outputs of a job this "
                                           "journal did not make"),
            std::string::npos)
      << second.status().ToString();
  std::ifstream kept(dir + "/kept.txt");
  std::string text;
  std::getline(kept, text);
  EXPECT_EQ(text, "an earlier job's output");
  // An empty directory of that name (nothing to lose) is taken.
  fs::remove_all(root_ + "/test-2");
  fs::create_directories(root_ + "/test-2");
  EXPECT_TRUE(scheduler_->Submit(PipelineIn(root_), {}, "p.yaml").ok());
}

TEST_F(SchedulerTest, ResumeAfterRestartNeverRerunsCommittedTasks) {
  auto job = scheduler_->Submit(PipelineIn(root_), {}, "p.yaml");
  scheduler_->OnReady("w1", ReadyFor("w1", 2));
  scheduler_->Dispatch();
  auto a = Assigned("w1");
  ASSERT_EQ(a.size(), 2u);
  scheduler_->OnResult("w1", Ok(a[0]));
  ASSERT_TRUE(scheduler_->FlushJournal().ok());
  // The coordinator dies (a[1] was running); a new one reads the journal.
  Reopen();
  ASSERT_TRUE(scheduler_->Resume().ok());
  scheduler_->OnReady("w2", ReadyFor("w2", 10));
  scheduler_->Dispatch();
  auto b = Assigned("w2");
  ASSERT_EQ(b.size(), 3u);  // 4 writes, 1 committed before the crash
  for (const auto& x : b) EXPECT_NE(x.task().index(), a[0].task().index());
  // A late result for an attempt of the dead coordinator is ignored.
  scheduler_->OnResult("w1", Ok(a[1]));
  EXPECT_EQ(StageOf(*job, "write").committed(), 1);
  for (const auto& x : b) scheduler_->OnResult("w2", Ok(x));
  scheduler_->Dispatch();
  auto c = Assigned("w2");
  ASSERT_EQ(c.size(), 1u);
  scheduler_->OnResult("w2", Ok(c[0]));
  EXPECT_EQ(scheduler_->JobState(*job), "succeeded");
}

TEST_F(SchedulerTest, CancelStopsAttemptsAndDiscardsTheirResults) {
  auto job = scheduler_->Submit(PipelineIn(root_), {}, "p.yaml");
  scheduler_->OnReady("w1", ReadyFor("w1", 2));
  scheduler_->Dispatch();
  auto a = Assigned("w1");
  ASSERT_TRUE(scheduler_->Cancel(*job).ok());
  int cancels = 0;
  for (const auto& o : scheduler_->TakeOutgoing()) cancels += o.cancel.has_value();
  EXPECT_EQ(cancels, 2);
  scheduler_->OnResult("w1", Ok(a[0]));
  EXPECT_EQ(scheduler_->JobState(*job), "cancelled");
  EXPECT_EQ(StageOf(*job, "write").committed(), 0);
  EXPECT_FALSE(scheduler_->Cancel(*job).ok());
  EXPECT_FALSE(scheduler_->Cancel(999).ok());
}

TEST_F(SchedulerTest, ScheduledPipelinesFireOnTheClock) {
  auto id = scheduler_->Submit("name: nightly\noutput_root: " + root_ +
                                   "\nschedule: '0 3 * * *'\nstages: {a: {kind: noop}}\n",
                               {}, "n.yaml");
  ASSERT_TRUE(id.ok());
  EXPECT_EQ(*id, 0);  // registered, not run
  EXPECT_TRUE(scheduler_->JobStatuses(0).empty());
  // Registered at 1.8e9 (2027-01-15 08:00 UTC): the first run is 2027-01-16 03:00.
  clock_ = FakeClock(static_cast<double>(Unix(2027, 1, 16, 2, 59)));
  Reopen();  // schedules come back from the journal too
  ASSERT_TRUE(scheduler_->Resume().ok());
  scheduler_->Tick();
  EXPECT_TRUE(scheduler_->JobStatuses(0).empty());
  clock_.Advance(120);
  scheduler_->Tick();
  ASSERT_EQ(scheduler_->JobStatuses(0).size(), 1u);
  EXPECT_EQ(scheduler_->JobStatuses(0)[0].name(), "nightly");
  scheduler_->Tick();
  EXPECT_EQ(scheduler_->JobStatuses(0).size(), 1u);  // once per fire time
}

// ---- protocol
// ------------------------------------------------------------------------------------

std::vector<zmq::message_t> Frames(std::vector<std::string> parts) {
  std::vector<zmq::message_t> frames;
  for (const auto& p : parts) frames.emplace_back(p.data(), p.size());
  return frames;
}

TEST(Protocol, HeaderGuardsEveryFrame) {
  net::Envelope e;
  wire::Heartbeat hb;
  const std::string body = hb.SerializeAsString();
  auto ok = Frames({"id", net::EncodeHeader(net::MessageType::kHeartbeat), body});
  EXPECT_EQ(net::DecodeFrames(ok, true, &e), net::DropReason::kNone);
  EXPECT_EQ(e.identity, "id");
  auto missing = Frames({"id", net::EncodeHeader(net::MessageType::kHeartbeat)});
  EXPECT_EQ(net::DecodeFrames(missing, true, &e), net::DropReason::kFrameCount);
  auto garbage = Frames({"id", "hello", body});
  EXPECT_EQ(net::DecodeFrames(garbage, true, &e), net::DropReason::kBadHeader);
  auto version = Frames({"id", std::string{'M', 'P', 9, 2}, body});
  EXPECT_EQ(net::DecodeFrames(version, true, &e), net::DropReason::kVersion);
  auto type = Frames({"id", std::string{'M', 'P', 1, 77}, body});
  EXPECT_EQ(net::DecodeFrames(type, true, &e), net::DropReason::kType);
  auto big = Frames(
      {net::EncodeHeader(net::MessageType::kReady), std::string(net::kMaxFrameBytes + 1, 'x')});
  EXPECT_EQ(net::DecodeFrames(big, false, &e), net::DropReason::kOversized);
  wire::Ready ready;
  EXPECT_FALSE(net::ParseBody(std::string("\xff\xff\xff\xff\xff", 5), &ready));
}

}  // namespace
}  // namespace motionpipe::coordinator

namespace motionpipe::worker {
namespace {

TEST(Security, AllowListKeysMayContainHash) {
  // '#' is a Z85 digit: generated keys contain it about once in five, and must not be cut there.
  const std::string with_hash = "rq:rM>}U?@Lns47E1%kR.o@n%FcmmsL/@{H8]yf#";
  const std::string plain = "Yne@$w-vo<fVvi]a<NY6T1ed:M$fCG*[IaLV{hID";
  const std::string path = ::testing::TempDir() + "/allow_hash.txt";
  ASSERT_TRUE(WriteFileAtomic(
                  path, "# workers\n" + with_hash + "\n  public-key: " + plain + "   # laptop\n\n")
                  .ok());
  auto keys = net::LoadAllowList(path);
  ASSERT_TRUE(keys.ok()) << keys.status().ToString();
  EXPECT_EQ(*keys, (std::set<std::string>{with_hash, plain}));
  ASSERT_TRUE(WriteFileAtomic(path, with_hash + " " + plain + "\n").ok());
  auto two = net::LoadAllowList(path);
  ASSERT_FALSE(two.ok());
  EXPECT_NE(two.status().message().find("allow_hash.txt:1"), std::string::npos);
  for (int k = 0; k < 20; ++k) {  // generated keys round-trip through an allow file
    auto pair = net::GenerateCurveKeyPair();
    ASSERT_TRUE(pair.ok());
    ASSERT_TRUE(WriteFileAtomic(path, pair->public_key + "\n").ok());
    auto loaded = net::LoadAllowList(path);
    ASSERT_TRUE(loaded.ok()) << pair->public_key << ": " << loaded.status().ToString();
    EXPECT_EQ(loaded->count(pair->public_key), 1u);
  }
}

TEST(PluginHost, LoadsTheSamplePluginAndRefusesBadOnes) {
  PluginHost host;
  ASSERT_TRUE(host.LoadFile(MOTIONPIPE_BUILD_DIR "/plugins/sample.so").ok());
  ASSERT_EQ(host.plugins().size(), 1u);
  EXPECT_EQ(host.plugins()[0].name, "sample");
  EXPECT_EQ(host.plugins()[0].stage_kinds,
            (std::vector<std::string>{"sample.checksum", "sample.echo"}));
  const auto expect_refused = [&](const std::string& file, const std::string& why) {
    const Status s = host.LoadFile(file);
    ASSERT_FALSE(s.ok()) << file;
    EXPECT_NE(s.message().find(why), std::string::npos) << s.message();
  };
  const unsigned abi = MOTIONPIPE_PLUGIN_ABI_VERSION;
  expect_refused(MOTIONPIPE_BUILD_DIR "/test_plugins/bad_abi.so",
                 "plugin ABI version " + std::to_string(abi + 41) + ", this host speaks version " +
                     std::to_string(abi));
  expect_refused(MOTIONPIPE_BUILD_DIR "/test_plugins/throws.so",
                 "entry point threw: cannot find my model weights");
  expect_refused(MOTIONPIPE_BUILD_DIR "/test_plugins/no_entry.so",
                 "no 'motionpipe_plugin_v1' symbol");
  const std::string not_a_library = ::testing::TempDir() + "/fake.so";
  std::ofstream(not_a_library) << "not ELF";
  expect_refused(not_a_library, "cannot load");
  EXPECT_TRUE(host.LoadFile(MOTIONPIPE_BUILD_DIR "/plugins/../plugins/sample.so")
                  .ok());  // same file again: no-op
  EXPECT_EQ(host.problems().size(), 4u);
  EXPECT_EQ(host.plugins().size(), 1u);  // the host kept going

  // The plugin's stage runs through the executor interface.
  ExecutorRegistry registry;
  host.RegisterExecutors(&registry);
  StageExecutor* echo = registry.Find("sample.echo");
  ASSERT_NE(echo, nullptr);
  TaskContext ctx;
  ctx.spec.set_output_dir(::testing::TempDir() + "/echo_out");
  ctx.spec.set_params_json("{\"answer\": 42}");
  const TaskReport report = RunTask(*echo, ctx);
  EXPECT_EQ(report.outcome, Outcome::kOk) << report.message;
  EXPECT_NE(ReadFile(ctx.spec.output_dir() + "/params.json")->find("42"), std::string::npos);
  StageExecutor* checksum = registry.Find("sample.checksum");
  TaskContext bad;
  bad.spec.set_output_dir(::testing::TempDir() + "/checksum_out");
  auto* input = bad.spec.add_inputs();
  input->set_stage("x");
  input->add_dirs("/no/such/dir");
  const TaskReport refused = RunTask(*checksum, bad);
  EXPECT_EQ(refused.outcome, Outcome::kBadInput);
  EXPECT_NE(refused.message.find("/no/such/dir is missing"), std::string::npos);
}

// A checkpoint's model is read from its model.json without loading weights (clean_legs refuses an
// editor's checkpoint before an MDT's weights are read), from any of the directories a user may
// name; a file that cannot say is named.
TEST(Generators, CheckpointModelNameIsReadWithoutLoading) {
  namespace fs = std::filesystem;
  const std::string stage = ::testing::TempDir() + "/checkpoint_name/cleanup";
  const std::string model = layout::CheckpointDir(layout::TaskDir(stage));
  fs::create_directories(model);
  std::ofstream(layout::ModelConfigFile(model)) << R"({"name": "leg_cleanup", "width": 8})";
  for (const std::string& path : {stage, layout::TaskDir(stage), model}) {
    const auto name = worker::CheckpointModelName(path);
    ASSERT_TRUE(name.ok()) << path << ": " << name.status().message();
    EXPECT_EQ(*name, "leg_cleanup");
  }
  const auto expect_refused = [&](const std::string& text, const std::string& why) {
    std::ofstream(layout::ModelConfigFile(model)) << text;
    const auto name = worker::CheckpointModelName(stage);
    ASSERT_FALSE(name.ok()) << text;
    EXPECT_NE(name.status().message().find(layout::ModelConfigFile(model)), std::string::npos)
        << name.status().message();
    EXPECT_NE(name.status().message().find(why), std::string::npos) << name.status().message();
  };
  expect_refused(R"({"width": 8})", "no model name");
  expect_refused(R"(["leg_cleanup"])", "no model name");
  expect_refused(R"({"name": 3})", "no model name");
  expect_refused("{\"name\": ", "parse error");
  const auto missing = worker::CheckpointModelName(stage + "/no_such");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.status().message().find("no such checkpoint directory"), std::string::npos);
}

// A stage kind is one unit: the executor a worker runs also plans the stage in the coordinator, so
// a new kind is one class registered once (issue 16). Here a kind unknown to the engine.
class ThreeShardsStage : public StageExecutor {
 public:
  std::string Description() const override { return "test kind"; }
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    plan.shards = IntParam(plan.params, "parts", 3, 1, path, errors);
    plan.reduce = true;
  }
  TaskReport Run(TaskContext&) override { return TaskReport::Ok(); }
};

TEST(Executors, AKindIsPlannedByTheExecutorThatRunsIt) {
  auto executors = std::make_shared<ExecutorRegistry>();
  executors->Register("test.three", std::make_unique<ThreeShardsStage>());
  const auto kinds = coordinator::KindRegistry::FromExecutors(executors);
  auto spec = coordinator::ParsePipeline("name: k\nstages:\n  a: {kind: test.three}\n", {},
                                         "k.yaml", kinds);
  ASSERT_TRUE(spec.ok()) << spec.status().ToString();
  EXPECT_EQ(spec->stages[0].shards, 3);
  EXPECT_TRUE(spec->stages[0].reduce);
  auto bad = coordinator::ParsePipeline(
      "name: k\nstages:\n  a: {kind: test.three, params: {parts: 0}}\n", {}, "k.yaml", kinds);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("k.yaml: stages.a.params.parts: must be an integer >= 1"),
            std::string::npos)
      << bad.status().message();
  // The built-in registry plans every kind the worker runs, and `train` (run by the train plugin).
  ExecutorRegistry builtins;
  RegisterBuiltinExecutors(&builtins);
  auto planned = coordinator::KindRegistry::WithBuiltins().Kinds();
  std::erase(planned, std::string("train"));
  EXPECT_EQ(builtins.Kinds(), planned);
}

TEST(Executors, OutputsAreScannedWithChecksums) {
  const std::string dir = ::testing::TempDir() + "/scan";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir + "/sub");
  std::ofstream(dir + "/b.txt") << "abc";
  std::ofstream(dir + "/sub/a.txt") << "";
  const auto outputs = ScanOutputs(dir);
  ASSERT_EQ(outputs.size(), 2u);
  EXPECT_EQ(outputs[0].path(), "b.txt");
  EXPECT_EQ(outputs[0].sha256(),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(outputs[1].path(), "sub/a.txt");
  EXPECT_TRUE(ScanOutputs(dir + "/missing").empty());
}

}  // namespace
}  // namespace motionpipe::worker
