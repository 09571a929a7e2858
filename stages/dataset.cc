// `dataset`: MotionFix and BABEL + AMASS laid out as the corpus stage lays out its result.
#include <filesystem>

#include "inputs.h"
#include "motionpipe/base/file.h"
#include "motionpipe/formats/motionfix.h"
#include "stage.h"

namespace motionpipe::stages {

namespace {

namespace fs = std::filesystem;

// `dataset`: real data in place of the procedural corpus, laid out as the corpus stage lays out its
// result, so that every later stage runs unchanged: DIR/motionfix/triplets-*.npz (converted
// MotionFix, tools/motionfix_convert.py), DIR/babel/{train,val,test}.json (BABEL) and
// DIR/amass_root (the AMASS root BABEL's feat_p paths are relative to). Files are linked, not
// copied. params: motionfix (converted .npz files or directories of them), babel (a directory
// holding train/val/test.json, or the files), amass_root. Either source may be absent.
class DatasetStage : public StageExecutor {
 public:
  // One task.
  void Plan(StagePlan& plan, const std::string& path,
            std::vector<std::string>* errors) const override {
    plan.shards = 1;
    plan.reduce = false;
    const auto& p = plan.params;
    if (!p.contains("motionfix") && !p.contains("babel"))
      errors->push_back(path +
                        ".params: give motionfix (converted .npz files) and/or babel + amass_root");
    if (p.contains("babel") && !p.contains("amass_root"))
      errors->push_back(path + ".params.amass_root: required with babel (the AMASS directory)");
  }
  std::string Description() const override {
    return "links real data (converted MotionFix, BABEL + AMASS) in the corpus layout";
  }
  TaskReport Run(TaskContext& ctx) override {
    const json& p = ctx.params;
    const std::string out = ctx.output_dir();
    fs::create_directories(out);
    const auto link = [](const std::string& target, const std::string& path) -> Status {
      std::error_code ec;
      fs::create_directories(fs::path(path).parent_path(), ec);
      fs::create_symlink(fs::absolute(target), path, ec);
      if (ec) return IoError(path + ": cannot link to " + target + ": " + ec.message());
      return Status::Ok();
    };
    json manifest = {{"motionfix", json::array()}, {"babel", json::array()}};
    for (const std::string& entry : StringList(p.value("motionfix", json()))) {
      std::vector<std::string> files;
      if (fs::is_directory(entry)) {
        for (const auto& e : fs::directory_iterator(entry)) {
          if (e.path().extension() == ".npz") files.push_back(e.path().string());
        }
      } else if (fs::is_regular_file(entry)) {
        files.push_back(entry);
      } else {
        return TaskReport::BadInput("dataset: params.motionfix: " + entry + " does not exist");
      }
      std::sort(files.begin(), files.end());
      for (const std::string& f : files) {
        auto columns =
            ReadTripletColumns(f, {0, -1, false, false});  // checked now, not in a later stage
        if (!columns.ok()) return TaskReport::BadInput("dataset: " + columns.status().message());
        const std::string name = fs::path(f).stem().string();
        const std::string linked = out + "/motionfix/" +
                                   (name.rfind("triplets", 0) == 0 ? name : "triplets-" + name) +
                                   ".npz";
        if (Status st = link(f, linked); !st.ok())
          return TaskReport::BadInput("dataset: " + st.message());
        manifest["motionfix"].push_back(
            {{"file", fs::absolute(f).string()}, {"triplets", columns->rows}});
      }
    }
    const json babel_param = p.value("babel", json());
    std::vector<std::pair<std::string, std::string>> babel;  // split file -> name
    for (const std::string& entry : StringList(babel_param)) {
      if (fs::is_directory(entry)) {
        for (const char* split : {"train", "val", "test"}) {
          if (fs::exists(entry + "/" + split + ".json"))
            babel.push_back({entry + "/" + split + ".json", split});
        }
      } else if (fs::is_regular_file(entry)) {
        babel.push_back({entry, fs::path(entry).stem().string()});
      } else {
        return TaskReport::BadInput("dataset: params.babel: " + entry + " does not exist");
      }
    }
    for (const auto& [file, split] : babel) {
      if (split != "train" && split != "val" && split != "test") {
        return TaskReport::BadInput("dataset: params.babel: " + file +
                                    ": BABEL files are named train.json, val.json or test.json");
      }
      if (Status st = link(file, out + "/babel/" + split + ".json"); !st.ok())
        return TaskReport::BadInput("dataset: " + st.message());
      manifest["babel"].push_back(fs::absolute(file).string());
    }
    if (!babel.empty()) {
      const std::string root = p.value("amass_root", std::string());
      if (root.empty() || !fs::is_directory(root))
        return TaskReport::BadInput(
            "dataset: params.amass_root: the AMASS directory BABEL's feat_p paths start from");
      if (Status st = WriteFileAtomic(out + "/amass_root", fs::absolute(root).string()); !st.ok())
        return TaskReport::Error(st.message());
      manifest["amass_root"] = fs::absolute(root).string();
    }
    if (manifest["motionfix"].empty() && babel.empty())
      return TaskReport::BadInput("dataset: give params.motionfix and/or params.babel");
    if (Status st = WriteFileAtomic(out + "/manifest.json", manifest.dump(1) + "\n"); !st.ok())
      return TaskReport::Error(st.message());
    return TaskReport::Ok();
  }
};

}  // namespace

MP_STAGE_KIND("dataset", DatasetStage);

}  // namespace motionpipe::stages
