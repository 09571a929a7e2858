// Sends malformed traffic for the engine's robustness tests.
//   motionpipe_garbage --connect ENDPOINT [--count N]   floods a coordinator's ROUTER (worker or
//   control) motionpipe_garbage --bind ENDPOINT [--count N] [--seconds S]
//                                                      plays a coordinator that sends garbage to
//                                                      the workers that connect to it
// Prints how many messages it sent.
#include <chrono>
#include <cstdio>
#include <cstring>
#include <random>
#include <set>
#include <string>
#include <thread>
#include <vector>
#include <zmq.hpp>

#include "motionpipe.pb.h"
#include "motionpipe/net/protocol.h"

namespace {

using motionpipe::net::EncodeHeader;
using motionpipe::net::MessageType;

std::string Random(std::mt19937& rng, size_t n) {
  std::string s(n, '\0');
  for (char& c : s) c = static_cast<char>(rng() & 0xFF);
  return s;
}

// One malformed (or unexpected) message as frames, never including a routing identity.
std::vector<std::string> Garbage(std::mt19937& rng, int kind) {
  switch (kind % 10) {
    case 0:
      return {Random(rng, 1 + rng() % 64)};  // one random frame
    case 1:
      return {"XX\x01\x02", Random(rng, 10)};  // bad magic
    case 2:
      return {std::string{'M', 'P', 99, 2}, ""};  // unknown version
    case 3:
      return {std::string{'M', 'P', 1, static_cast<char>(200)}, ""};  // unknown type
    case 4:
      return {EncodeHeader(MessageType::kTaskResult), Random(rng, 40)};  // undecodable body
    case 5:
      return {EncodeHeader(MessageType::kReady), Random(rng, 8),
              Random(rng, 8)};  // too many frames
    case 6:
      return {EncodeHeader(MessageType::kAssign), std::string((16u << 20) + 1, 'x')};  // oversized
    case 7: {  // result for an unknown attempt
      motionpipe::wire::TaskResult r;
      r.set_attempt_id(static_cast<int64_t>(rng()));
      r.set_outcome(motionpipe::wire::TaskResult::OK);
      return {EncodeHeader(MessageType::kTaskResult), r.SerializeAsString()};
    }
    case 8:
      return {EncodeHeader(MessageType::kControlReply), ""};  // wrong direction
    default: {
      std::vector<std::string> many;
      for (int k = 0; k < 40; ++k) many.push_back(Random(rng, 3));  // a frame flood
      return many;
    }
  }
}

void SendFrames(zmq::socket_t& socket, const std::string* identity,
                const std::vector<std::string>& frames) {
  try {
    if (identity)
      socket.send(zmq::buffer(*identity), zmq::send_flags::sndmore | zmq::send_flags::dontwait);
    for (size_t k = 0; k < frames.size(); ++k) {
      socket.send(zmq::buffer(frames[k]),
                  (k + 1 < frames.size() ? zmq::send_flags::sndmore : zmq::send_flags::none) |
                      zmq::send_flags::dontwait);
    }
  } catch (const zmq::error_t&) {
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::string connect, bind;
  int count = 200;
  double seconds = 5;
  for (int k = 1; k < argc; ++k) {
    if (!std::strcmp(argv[k], "--connect") && k + 1 < argc)
      connect = argv[++k];
    else if (!std::strcmp(argv[k], "--bind") && k + 1 < argc)
      bind = argv[++k];
    else if (!std::strcmp(argv[k], "--count") && k + 1 < argc)
      count = std::atoi(argv[++k]);
    else if (!std::strcmp(argv[k], "--seconds") && k + 1 < argc)
      seconds = std::atof(argv[++k]);
  }
  std::mt19937 rng(12345);
  zmq::context_t context(1);
  int sent = 0;
  if (!connect.empty()) {
    zmq::socket_t socket(context, zmq::socket_type::dealer);
    socket.set(zmq::sockopt::linger, 2000);
    socket.connect(connect);
    for (int k = 0; k < count; ++k, ++sent) SendFrames(socket, nullptr, Garbage(rng, k));
  } else if (!bind.empty()) {
    zmq::socket_t socket(context, zmq::socket_type::router);
    socket.set(zmq::sockopt::linger, 2000);
    socket.bind(bind);
    std::set<std::string> peers;
    const auto end = std::chrono::steady_clock::now() +
                     std::chrono::milliseconds(static_cast<int>(seconds * 1000));
    while (std::chrono::steady_clock::now() < end && sent < count) {
      zmq::pollitem_t item{socket.handle(), 0, ZMQ_POLLIN, 0};
      zmq::poll(&item, 1, std::chrono::milliseconds(50));
      zmq::message_t frame;
      while (socket.recv(frame, zmq::recv_flags::dontwait)) {
        peers.insert(frame.to_string());  // the identity frame (the rest of the message is skipped)
        while (frame.more() && socket.recv(frame, zmq::recv_flags::dontwait)) {
        }
      }
      for (const std::string& peer : peers) {
        for (int k = 0; k < 10 && sent < count; ++k, ++sent)
          SendFrames(socket, &peer, Garbage(rng, sent));
      }
    }
  }
  std::printf("%d\n", sent);
  return 0;
}
