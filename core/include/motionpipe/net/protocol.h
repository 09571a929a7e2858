// The motionpipe wire format (ARCHITECTURE.md, "Processes and protocol"): every message is a 4-byte
// header frame {'M', 'P', version, type} followed by one Protobuf frame (proto/motionpipe.proto).
// Anything else (unknown versions or types, oversized or undecodable frames, wrong frame counts) is
// dropped with a reason that callers count and log; it never crashes either side.
#pragma once

#include <google/protobuf/message_lite.h>

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>
#include <zmq.hpp>

namespace motionpipe::net {

constexpr uint8_t kProtocolVersion = 1;
// A frame larger than this is refused before parsing (a task result with many outputs stays far
// below).
constexpr size_t kMaxFrameBytes = 16u << 20;

enum class MessageType : uint8_t {
  kReady = 1,
  kHeartbeat = 2,
  kAssign = 3,
  kTaskResult = 4,
  kCancel = 5,
  kDrain = 6,
  kDisconnect = 7,
  kControlRequest = 8,
  kControlReply = 9,
};
const char* MessageTypeName(MessageType type);

enum class DropReason { kNone, kFrameCount, kBadHeader, kVersion, kType, kOversized, kUndecodable };
const char* DropReasonName(DropReason reason);

// A received message: the peer identity (ROUTER side only), its type and the Protobuf body bytes.
struct Envelope {
  std::string identity;
  MessageType type = MessageType::kHeartbeat;
  std::string body;
};

std::string EncodeHeader(MessageType type);
// Validates [identity?][header][body] frames; `has_identity` for ROUTER sockets.
DropReason DecodeFrames(std::vector<zmq::message_t>& frames, bool has_identity, Envelope* out);

// Sends [identity?][header][body]. Returns false when the socket would block or the peer is gone
// (ROUTER with ZMQ_ROUTER_MANDATORY), never throws for those.
bool Send(zmq::socket_t& socket, const std::string* identity, MessageType type,
          const google::protobuf::MessageLite& body);
// Receives all frames of one message without blocking; false when nothing is waiting.
bool ReceiveFrames(zmq::socket_t& socket, std::vector<zmq::message_t>* frames);

// zmq::poll that returns 0 instead of throwing when a signal interrupts it (SIGTERM starts a
// drain).
int Poll(zmq::pollitem_t* items, size_t count, std::chrono::milliseconds timeout);

// Parses `body` into `message`; false for undecodable bytes.
bool ParseBody(const std::string& body, google::protobuf::MessageLite* message);

}  // namespace motionpipe::net
