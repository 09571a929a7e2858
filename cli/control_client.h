// Talks to a coordinator's control socket: one request, one reply, with a timeout.
#pragma once

#include <string>

#include "motionpipe.pb.h"
#include "motionpipe/base/status.h"

namespace motionpipe::cli {

// Default control endpoint: $MOTIONPIPE_CONTROL or tcp://127.0.0.1:5556.
std::string DefaultControlEndpoint();

Result<wire::ControlReply> Control(const std::string& endpoint, const wire::ControlRequest& request,
                                   double timeout_seconds = 10);

// Job and stage lines for people: progress bars on a terminal (`tty`), plain lines otherwise.
// compact: only the stages running or failing, after the job's progress line (long pipelines).
std::string FormatStatus(const wire::ControlReply& reply, bool tty, bool show_workers,
                         bool compact = false);

}  // namespace motionpipe::cli
