// CurveZMQ for the worker <-> coordinator link: key pairs, key files, and a ZAP handler that admits
// only workers whose public key is on an allow-list (ARCHITECTURE.md, "Security").
#pragma once

#include <atomic>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <zmq.hpp>

#include "motionpipe/base/status.h"

namespace motionpipe::net {

struct CurveKeyPair {
  std::string public_key;  // Z85, 40 characters
  std::string secret_key;
};

Result<CurveKeyPair> GenerateCurveKeyPair();
// Key files hold "public-key: <z85>" and "secret-key: <z85>" lines ('#' comments allowed); a file
// with only the public line is a public key file.
std::string FormatKeyFile(const CurveKeyPair& keys);
Result<CurveKeyPair> LoadKeyFile(const std::string& path);
// One Z85 public key per line; blank lines, "public-key:" prefixes, comment lines starting with '#'
// and comments after whitespace are allowed ('#' itself is a Z85 digit, so it may occur in keys).
Result<std::set<std::string>> LoadAllowList(const std::string& path);

// Runs the ZAP handler (inproc://zeromq.zap.01) on its own thread: CURVE clients whose key is in
// `allowed` are admitted, all others refused (status 400) and counted. Must share the server
// socket's context and start before that socket binds.
class ZapAuthenticator {
 public:
  ZapAuthenticator(zmq::context_t& context, std::set<std::string> allowed);
  ~ZapAuthenticator();
  int64_t refused() const { return refused_.load(); }
  int64_t admitted() const { return admitted_.load(); }

 private:
  void Loop();
  zmq::context_t& context_;
  std::set<std::string> allowed_;
  std::atomic<bool> stop_{false};
  std::atomic<int64_t> refused_{0}, admitted_{0};
  std::unique_ptr<zmq::socket_t> socket_;
  std::thread thread_;
};

// Makes `socket` a CURVE server (coordinator) or client (worker).
void ConfigureCurveServer(zmq::socket_t& socket, const CurveKeyPair& server_keys);
void ConfigureCurveClient(zmq::socket_t& socket, const CurveKeyPair& client_keys,
                          const std::string& server_public_key);

}  // namespace motionpipe::net
