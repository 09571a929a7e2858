// Subcommand registration for the single `motionpipe` binary. Each group adds its subcommands to
// the app; a command's callback stores its exit code in `*exit_code`.
#pragma once

#include <CLI/CLI.hpp>

namespace motionpipe::cli {

// Exit codes: 0 success, 1 the operation failed (bad input file, I/O), 2 usage error.
constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;
constexpr int kExitUsage = 2;

void AddDataCommands(CLI::App& app, int* exit_code);
void AddEngineCommands(CLI::App& app, int* exit_code);
void AddLabelsCommands(CLI::App& app, int* exit_code);
void AddSincCommands(CLI::App& app, int* exit_code);
void AddModelCommands(CLI::App& app, int* exit_code);

}  // namespace motionpipe::cli
