#include "motionpipe/net/security.h"

#include <sstream>

#include "motionpipe/base/file.h"
#include "motionpipe/base/log.h"
#include "motionpipe/net/protocol.h"

namespace motionpipe::net {

namespace {
std::string Trim(const std::string& s) {
  const size_t b = s.find_first_not_of(" \t\r\n");
  const size_t e = s.find_last_not_of(" \t\r\n");
  return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
}
bool ValidZ85Key(const std::string& key) {
  if (key.size() != 40) return false;
  uint8_t decoded[32];
  return zmq_z85_decode(decoded, key.c_str()) != nullptr;
}
}  // namespace

Result<CurveKeyPair> GenerateCurveKeyPair() {
  char pub[41], sec[41];
  if (zmq_curve_keypair(pub, sec) != 0) return Internal("libzmq was built without CURVE support");
  return CurveKeyPair{pub, sec};
}

std::string FormatKeyFile(const CurveKeyPair& keys) {
  return "# motionpipe CurveZMQ key pair: share the public key, keep this file private (chmod "
         "600)\n"
         "public-key: " +
         keys.public_key + "\nsecret-key: " + keys.secret_key + "\n";
}

Result<CurveKeyPair> LoadKeyFile(const std::string& path) {
  MP_ASSIGN_OR_RETURN(const std::string text, ReadFile(path));
  CurveKeyPair keys;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    line = Trim(line);
    if (line.empty() || line[0] == '#') continue;
    const size_t colon = line.find(':');
    if (colon == std::string::npos)
      return DataLoss(path + ": expected 'public-key: ...' or 'secret-key: ...'");
    const std::string key = Trim(line.substr(0, colon)), value = Trim(line.substr(colon + 1));
    if (!ValidZ85Key(value))
      return DataLoss(path + ": '" + key + "' is not a 40-character Z85 key");
    if (key == "public-key")
      keys.public_key = value;
    else if (key == "secret-key")
      keys.secret_key = value;
    else
      return DataLoss(path + ": unknown entry '" + key + "'");
  }
  if (keys.public_key.empty()) return DataLoss(path + ": no public-key line");
  return keys;
}

Result<std::set<std::string>> LoadAllowList(const std::string& path) {
  MP_ASSIGN_OR_RETURN(const std::string text, ReadFile(path));
  std::set<std::string> keys;
  std::istringstream in(text);
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    // '#' is a Z85 digit, so a comment is a line that starts with '#' or text after whitespace.
    line = Trim(line);
    if (line.empty() || line[0] == '#') continue;
    if (line.rfind("public-key:", 0) == 0) line = Trim(line.substr(11));
    const size_t space = line.find_first_of(" \t");
    if (space != std::string::npos) {
      const std::string rest = Trim(line.substr(space));
      if (!rest.empty() && rest[0] != '#') {
        return DataLoss(path + ":" + std::to_string(number) +
                        ": one key per line (comments start with '#')");
      }
      line.resize(space);
    }
    if (!ValidZ85Key(line))
      return DataLoss(path + ":" + std::to_string(number) + ": not a 40-character Z85 public key");
    keys.insert(line);
  }
  return keys;
}

ZapAuthenticator::ZapAuthenticator(zmq::context_t& context, std::set<std::string> allowed)
    : context_(context), allowed_(std::move(allowed)) {
  socket_ = std::make_unique<zmq::socket_t>(context_, zmq::socket_type::rep);
  socket_->set(zmq::sockopt::linger, 0);
  socket_->bind("inproc://zeromq.zap.01");
  thread_ = std::thread([this] { Loop(); });
}

ZapAuthenticator::~ZapAuthenticator() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
}

void ZapAuthenticator::Loop() {
  zmq::pollitem_t item{socket_->handle(), 0, ZMQ_POLLIN, 0};
  while (!stop_) {
    try {
      if (Poll(&item, 1, std::chrono::milliseconds(100)) <= 0) continue;
      // ZAP request: version, request id, domain, address, identity, mechanism, credentials...
      std::vector<zmq::message_t> frames;
      while (true) {
        zmq::message_t frame;
        if (!socket_->recv(frame)) break;
        const bool more = frame.more();
        frames.push_back(std::move(frame));
        if (!more) break;
      }
      const std::string version = frames.size() > 0 ? frames[0].to_string() : "";
      const std::string request_id = frames.size() > 1 ? frames[1].to_string() : "";
      const std::string mechanism = frames.size() > 5 ? frames[5].to_string() : "";
      std::string status = "400", text = "refused";
      if (mechanism == "CURVE" && frames.size() > 6 && frames[6].size() == 32) {
        char z85[41];
        zmq_z85_encode(z85, static_cast<const uint8_t*>(frames[6].data()), 32);
        if (allowed_.count(z85)) {
          status = "200";
          text = "OK";
          ++admitted_;
        } else {
          ++refused_;
          MP_LOG(kWarn, "security") << "refused a worker with unknown CURVE key " << z85;
        }
      } else {
        ++refused_;
      }
      socket_->send(zmq::buffer(version.empty() ? std::string("1.0") : version),
                    zmq::send_flags::sndmore);
      socket_->send(zmq::buffer(request_id), zmq::send_flags::sndmore);
      socket_->send(zmq::buffer(status), zmq::send_flags::sndmore);
      socket_->send(zmq::buffer(text), zmq::send_flags::sndmore);
      socket_->send(zmq::str_buffer(""), zmq::send_flags::sndmore);
      socket_->send(zmq::str_buffer(""), zmq::send_flags::none);
    } catch (const zmq::error_t& error) {
      if (error.num() == ETERM) return;
      MP_LOG(kWarn, "security") << "ZAP handler: " << error.what();
    }
  }
}

void ConfigureCurveServer(zmq::socket_t& socket, const CurveKeyPair& server_keys) {
  socket.set(zmq::sockopt::curve_server, 1);
  socket.set(zmq::sockopt::curve_secretkey, server_keys.secret_key);
  socket.set(zmq::sockopt::zap_domain, "motionpipe");
}

void ConfigureCurveClient(zmq::socket_t& socket, const CurveKeyPair& client_keys,
                          const std::string& server_public_key) {
  socket.set(zmq::sockopt::curve_serverkey, server_public_key);
  socket.set(zmq::sockopt::curve_publickey, client_keys.public_key);
  socket.set(zmq::sockopt::curve_secretkey, client_keys.secret_key);
}

}  // namespace motionpipe::net
