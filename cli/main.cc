// motionpipe: one binary, many subcommands (ARCHITECTURE.md, "Processes and protocol").
#include <CLI/CLI.hpp>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <string>

#include "commands.h"
#include "motionpipe/base/log.h"

int main(int argc, char** argv) {
  CLI::App app{
      "motionpipe: distributed batch pipelines for 3D human-motion research (SimMotionEdit, SINC)"};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("motionpipe ") + MOTIONPIPE_VERSION);
  std::string log_level = "info";
  app.add_option("--log", log_level, "Log level: debug, info, warn, error")
      ->envname("MOTIONPIPE_LOG");
  int exit_code = motionpipe::cli::kExitOk;
  motionpipe::cli::AddDataCommands(app, &exit_code);
  motionpipe::cli::AddEngineCommands(app, &exit_code);
  motionpipe::cli::AddLabelsCommands(app, &exit_code);
  motionpipe::cli::AddSincCommands(app, &exit_code);
  motionpipe::cli::AddModelCommands(app, &exit_code);
  app.parse_complete_callback([&] {
    motionpipe::LogLevel level;
    if (!motionpipe::ParseLogLevel(log_level, &level))
      throw CLI::ValidationError("--log", "unknown level " + log_level);
    motionpipe::SetLogLevel(level);
  });
  // The first word that is not an option must name a command: CLI11 alone would answer an unknown
  // one with "A subcommand is required".
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--log")) {
      ++i;
      continue;
    }
    if (argv[i][0] == '-') continue;
    std::string known;
    bool found = false;
    for (const CLI::App* command : app.get_subcommands([](CLI::App*) { return true; })) {
      found = found || command->get_name() == argv[i];
      known += (known.empty() ? "" : ", ") + command->get_name();
    }
    if (!found) {
      std::fprintf(stderr, "motionpipe: unknown command '%s' (commands: %s; motionpipe --help)\n",
                   argv[i], known.c_str());
      return motionpipe::cli::kExitUsage;
    }
    break;
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return motionpipe::cli::kExitUsage;
  }
  return exit_code;
}
