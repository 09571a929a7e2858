// Subcommand registration for the single `motionpipe` binary. Each group adds its subcommands to
// the app. A command is an args struct (CLI11 writes the parsed options into a static one), a run
// function that takes it and returns the exit code, and an Add function that declares the options
// and stores the run function's result in `*exit_code`.
#pragma once

#include <CLI/CLI.hpp>
#include <algorithm>
#include <iostream>
#include <string>
#include <vector>

#include "motionpipe/base/status.h"
#include "motionpipe/formats/clip.h"

namespace motionpipe::cli {

// Exit codes: 0 success, 1 the operation failed (bad input file, I/O), 2 usage error.
constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;
constexpr int kExitUsage = 2;

// An operation that failed: the message on stderr, exit code 1.
inline int Fail(const Status& status) {
  std::cerr << "error: " << status.message() << "\n";
  return kExitFailure;
}

// A usage error found after parsing (options that contradict each other, an output name of the
// wrong kind): the message on stderr, exit code 2, as CLI11's own usage errors.
inline int Usage(const std::string& message) {
  std::cerr << "error: " << message << "\n";
  return kExitUsage;
}

// The clip `id` of a motion file's clips, or the first when `id` is empty.
inline Result<const Clip*> FindClip(const std::vector<Clip>& clips, const std::string& id,
                                    const std::string& file) {
  const auto it = id.empty() ? clips.begin()
                             : std::find_if(clips.begin(), clips.end(),
                                            [&](const Clip& c) { return c.id == id; });
  if (it == clips.end()) return NotFound(file + ": no clip '" + id + "'");
  return &*it;
}

void AddDataCommands(CLI::App& app, int* exit_code);
void AddEngineCommands(CLI::App& app, int* exit_code);
void AddLabelsCommands(CLI::App& app, int* exit_code);
void AddSincCommands(CLI::App& app, int* exit_code);
void AddModelCommands(CLI::App& app, int* exit_code);

}  // namespace motionpipe::cli
