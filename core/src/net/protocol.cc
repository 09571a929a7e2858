#include "motionpipe/net/protocol.h"

namespace motionpipe::net {

const char* MessageTypeName(MessageType type) {
  switch (type) {
    case MessageType::kReady:
      return "ready";
    case MessageType::kHeartbeat:
      return "heartbeat";
    case MessageType::kAssign:
      return "assign";
    case MessageType::kTaskResult:
      return "task_result";
    case MessageType::kCancel:
      return "cancel";
    case MessageType::kDrain:
      return "drain";
    case MessageType::kDisconnect:
      return "disconnect";
    case MessageType::kControlRequest:
      return "control_request";
    case MessageType::kControlReply:
      return "control_reply";
  }
  return "unknown";
}

const char* DropReasonName(DropReason reason) {
  switch (reason) {
    case DropReason::kNone:
      return "none";
    case DropReason::kFrameCount:
      return "frame_count";
    case DropReason::kBadHeader:
      return "bad_header";
    case DropReason::kVersion:
      return "version";
    case DropReason::kType:
      return "type";
    case DropReason::kOversized:
      return "oversized";
    case DropReason::kUndecodable:
      return "undecodable";
  }
  return "unknown";
}

std::string EncodeHeader(MessageType type) {
  return std::string{'M', 'P', static_cast<char>(kProtocolVersion), static_cast<char>(type)};
}

DropReason DecodeFrames(std::vector<zmq::message_t>& frames, bool has_identity, Envelope* out) {
  const size_t expected = has_identity ? 3 : 2;
  if (frames.size() != expected) return DropReason::kFrameCount;
  size_t at = 0;
  if (has_identity) out->identity = frames[at++].to_string();
  const zmq::message_t& header = frames[at++];
  const zmq::message_t& body = frames[at];
  if (header.size() != 4) return DropReason::kBadHeader;
  const auto* h = static_cast<const unsigned char*>(header.data());
  if (h[0] != 'M' || h[1] != 'P') return DropReason::kBadHeader;
  if (h[2] != kProtocolVersion) return DropReason::kVersion;
  if (h[3] < static_cast<unsigned char>(MessageType::kReady) ||
      h[3] > static_cast<unsigned char>(MessageType::kControlReply)) {
    return DropReason::kType;
  }
  if (body.size() > kMaxFrameBytes) return DropReason::kOversized;
  out->type = static_cast<MessageType>(h[3]);
  out->body.assign(static_cast<const char*>(body.data()), body.size());
  return DropReason::kNone;
}

bool Send(zmq::socket_t& socket, const std::string* identity, MessageType type,
          const google::protobuf::MessageLite& body) {
  std::string payload;
  if (!body.SerializeToString(&payload)) return false;
  const std::string header = EncodeHeader(type);
  try {
    if (identity &&
        !socket.send(zmq::buffer(*identity), zmq::send_flags::sndmore | zmq::send_flags::dontwait))
      return false;
    if (!socket.send(zmq::buffer(header), zmq::send_flags::sndmore | zmq::send_flags::dontwait))
      return false;
    return socket.send(zmq::buffer(payload), zmq::send_flags::dontwait).has_value();
  } catch (const zmq::error_t&) {
    return false;  // EHOSTUNREACH with ROUTER_MANDATORY: the peer is gone
  }
}

bool ReceiveFrames(zmq::socket_t& socket, std::vector<zmq::message_t>* frames) {
  frames->clear();
  while (true) {
    zmq::message_t frame;
    if (!socket.recv(frame, zmq::recv_flags::dontwait)) return !frames->empty();
    const bool more = frame.more();
    frames->push_back(std::move(frame));
    if (!more) return true;
    if (frames->size() > 16) {  // a flood of frames: drain and report as one bad message
      zmq::message_t rest;
      while (socket.recv(rest, zmq::recv_flags::dontwait) && rest.more()) {
      }
      return true;
    }
  }
}

int Poll(zmq::pollitem_t* items, size_t count, std::chrono::milliseconds timeout) {
  try {
    return zmq::poll(items, count, timeout);
  } catch (const zmq::error_t& e) {
    if (e.num() == EINTR) return 0;
    throw;
  }
}

bool ParseBody(const std::string& body, google::protobuf::MessageLite* message) {
  return message->ParseFromString(body);
}

}  // namespace motionpipe::net
