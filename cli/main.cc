// motionpipe: one binary, many subcommands (ARCHITECTURE.md, "Processes and protocol").
#include <CLI/CLI.hpp>

#include <iostream>

#include "commands.h"
#include "motionpipe/base/log.h"

int main(int argc, char** argv) {
  CLI::App app{"motionpipe: distributed batch pipelines for 3D human-motion research (SimMotionEdit, SINC)"};
  app.require_subcommand(1);
  std::string log_level = "info";
  app.add_option("--log", log_level, "Log level: debug, info, warn, error")->envname("MOTIONPIPE_LOG");
  int exit_code = motionpipe::cli::kExitOk;
  motionpipe::cli::AddDataCommands(app, &exit_code);
  motionpipe::cli::AddEngineCommands(app, &exit_code);
  motionpipe::cli::AddLabelsCommands(app, &exit_code);
  motionpipe::cli::AddSincCommands(app, &exit_code);
  motionpipe::cli::AddModelCommands(app, &exit_code);
  app.parse_complete_callback([&] {
    motionpipe::LogLevel level;
    if (!motionpipe::ParseLogLevel(log_level, &level)) throw CLI::ValidationError("--log", "unknown level " + log_level);
    motionpipe::SetLogLevel(level);
  });
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return motionpipe::cli::kExitUsage;
  }
  return exit_code;
}
