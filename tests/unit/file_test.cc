#include "motionpipe/base/file.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "motionpipe/base/job_layout.h"
#include "motionpipe/base/yaml.h"

namespace motionpipe {
namespace {

TEST(Sha256, KnownVectors) {
  EXPECT_EQ(Sha256Hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(Sha256Hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(Sha256Hex("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq"),
            "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
  EXPECT_EQ(Sha256Hex(std::string(1000000, 'a')),
            "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
}

TEST(File, AtomicWriteReplacesAndLeavesNoTemporaries) {
  const std::string dir = ::testing::TempDir() + "/atomic";
  ASSERT_TRUE(MakeDirs(dir).ok());
  const std::string path = dir + "/out.txt";
  ASSERT_TRUE(WriteFileAtomic(path, "first").ok());
  ASSERT_TRUE(WriteFileAtomic(path, "second").ok());
  EXPECT_EQ(*ReadFile(path), "second");
  int entries = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir))
    entries += entry.is_regular_file();
  EXPECT_EQ(entries, 1);
  EXPECT_EQ(ReadFile(dir + "/missing").status().code(), StatusCode::kNotFound);
  EXPECT_FALSE(WriteFileAtomic(dir + "/no/such/dir/file", "x").ok());
}

// Whether the parents' entries reach the disk is the power-loss test's (engine.disk_faults); here:
// the directories appear, an existing path is fine, and a path through a file is an error naming
// it.
TEST(File, MakeDirsDurableCreatesTheMissingChain) {
  const std::string root = ::testing::TempDir() + "/durable";
  std::filesystem::remove_all(root);
  ASSERT_TRUE(MakeDirsDurable(root + "/a/b/c").ok());
  EXPECT_TRUE(std::filesystem::is_directory(root + "/a/b/c"));
  EXPECT_TRUE(MakeDirsDurable(root + "/a/b").ok());
  ASSERT_TRUE(WriteFileAtomic(root + "/file", "x").ok());
  const Status through_file = MakeDirsDurable(root + "/file/d");
  EXPECT_FALSE(through_file.ok());
  EXPECT_NE(through_file.message().find(root + "/file/d"), std::string::npos)
      << through_file.message();
}

TEST(FileLock, OneHolderAtATimeNamedByPid) {
  const std::string dir = ::testing::TempDir() + "/lock";
  ASSERT_TRUE(MakeDirs(dir).ok());
  const std::string path = dir + "/journal.sqlite.lock";
  {
    auto first = FileLock::Acquire(path);
    ASSERT_TRUE(first.ok()) << first.status().message();
    // flock belongs to the open file: a second open of the same file conflicts, even in this
    // process.
    const auto second = FileLock::Acquire(path);
    ASSERT_FALSE(second.ok());
    EXPECT_EQ(second.status().code(), StatusCode::kFailedPrecondition);
    EXPECT_NE(second.status().message().find(path), std::string::npos) << second.status().message();
    EXPECT_NE(second.status().message().find("(pid " + std::to_string(::getpid()) + ")"),
              std::string::npos)
        << second.status().message();
    FileLock moved = std::move(*first);  // the lock moves with the object
    EXPECT_FALSE(FileLock::Acquire(path).ok());
  }
  EXPECT_TRUE(FileLock::Acquire(path).ok());  // released with its holder
  EXPECT_EQ(FileLock::Acquire(dir + "/no/such/dir/lock").status().code(), StatusCode::kIoError);
}

// A stage's output directories come in the order its inputs list them (result first, tasks by
// name), whatever order the file system gives; other entries are not outputs; a directory with
// neither is taken as it is (a task directory or a user's folder given directly).
TEST(JobLayout, StageOutputDirsPutTheResultFirstThenTheTasks) {
  namespace fs = std::filesystem;
  const std::string stage = ::testing::TempDir() + "/stage_output_dirs";
  fs::remove_all(stage);
  for (const char* name : {"task-00001", "task-00010", "task-00000", "result", ".staging", "logs"})
    fs::create_directories(stage + "/" + name);
  std::ofstream(stage + "/task-00002") << "a file, not a task";
  EXPECT_EQ(layout::StageOutputDirs(stage),
            (std::vector<std::string>{stage + "/result", stage + "/task-00000",
                                      stage + "/task-00001", stage + "/task-00010"}));
  fs::remove_all(stage + "/result");
  EXPECT_EQ(layout::StageOutputDirs(stage).front(), stage + "/task-00000");
  EXPECT_EQ(layout::StageOutputDirs(stage + "/task-00001"),
            std::vector<std::string>{stage + "/task-00001"});
  EXPECT_EQ(layout::StageOutputDirs(stage + "/missing"),
            std::vector<std::string>{stage + "/missing"});
  fs::remove_all(stage);
}

// Issue 16: the job's on-disk names have one home; these are the names jobs already on disk use
// (changing one would orphan every earlier job's outputs, so the test pins them).
TEST(JobLayout, NamesAreTheOnesJobsUse) {
  EXPECT_EQ(layout::TaskDirName(0), "task-00000");
  EXPECT_EQ(layout::TaskDirName(123456), "task-123456");
  EXPECT_EQ(layout::TaskDir("out/demo-1/train"), "out/demo-1/train/task-00000");
  EXPECT_EQ(layout::TaskDir("s", 12), "s/task-00012");
  EXPECT_EQ(layout::CheckpointDir("t"), "t/model");
  EXPECT_EQ(layout::ModelConfigFile("t/model"), "t/model/model.json");
  EXPECT_EQ(layout::ModelWeightsFile("t/model"), "t/model/model.pt");
  EXPECT_EQ(layout::RankSummaryFile("t", 1), "t/rank-1.json");
  EXPECT_EQ(layout::LossesFile("t"), "t/losses.csv");
  EXPECT_EQ(layout::ValLossesFile("t"), "t/val_losses.csv");
  EXPECT_EQ(layout::MetricsFile("t"), "t/metrics.json");
  EXPECT_EQ(layout::ShowcaseFile("t"), "t/showcase.json");
  EXPECT_STREQ(layout::kResultDirName, "result");
}

// One YAML converter for pipelines and papers: YAML 1.2 core-schema scalars, quoted scalars stay
// strings, keys keep the document's order, errors name origin:line:column.
TEST(Yaml, ScalarsAsTheCoreSchemaAndErrorsWithTheirPlace) {
  auto doc = ParseYaml("b: 2\na: [1.5, true, ~, '7', x]\n", "p.yaml");
  ASSERT_TRUE(doc.ok()) << doc.status().ToString();
  EXPECT_EQ(doc->dump(), R"({"b":2,"a":[1.5,true,null,"7","x"]})");
  auto bad = ParseYaml("a: [1,\n", "p.yaml");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(bad.status().message().rfind("p.yaml:", 0), 0u) << bad.status().message();
  EXPECT_NE(bad.status().message().find("malformed YAML"), std::string::npos);
}

}  // namespace
}  // namespace motionpipe
