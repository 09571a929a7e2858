#include "llm.h"

#include <curl/curl.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <mutex>
#include <thread>

#include "motionpipe/base/file.h"
#include "motionpipe/base/log.h"

namespace motionpipe::labels {

namespace {

constexpr char kPromptVersion[] = "sinc-fewshot-1";

size_t AppendBody(char* data, size_t size, size_t count, void* user) {
  static_cast<std::string*>(user)->append(data, size * count);
  return size * count;
}

void InitCurlOnce() {
  static std::once_flag once;
  std::call_once(once, [] { curl_global_init(CURL_GLOBAL_DEFAULT); });
}

struct HttpResult {
  long status = 0;
  std::string body;
  std::string error;  // transport error (no HTTP status)
};

HttpResult Post(const std::string& url, const std::string& body, const std::string& api_key,
                double timeout) {
  InitCurlOnce();
  HttpResult result;
  CURL* curl = curl_easy_init();
  if (!curl) {
    result.error = "curl_easy_init failed";
    return result;
  }
  curl_slist* headers = curl_slist_append(nullptr, "Content-Type: application/json");
  if (!api_key.empty())
    headers = curl_slist_append(headers, ("Authorization: Bearer " + api_key).c_str());
  char error[CURL_ERROR_SIZE] = {0};
  curl_easy_setopt(curl, CURLOPT_URL, url.c_str());
  curl_easy_setopt(curl, CURLOPT_HTTPHEADER, headers);
  curl_easy_setopt(curl, CURLOPT_POSTFIELDS, body.c_str());
  curl_easy_setopt(curl, CURLOPT_POSTFIELDSIZE, static_cast<long>(body.size()));
  curl_easy_setopt(curl, CURLOPT_WRITEFUNCTION, AppendBody);
  curl_easy_setopt(curl, CURLOPT_WRITEDATA, &result.body);
  curl_easy_setopt(curl, CURLOPT_TIMEOUT_MS, static_cast<long>(timeout * 1000));
  curl_easy_setopt(curl, CURLOPT_CONNECTTIMEOUT_MS,
                   static_cast<long>(std::min(timeout, 10.0) * 1000));
  curl_easy_setopt(curl, CURLOPT_NOSIGNAL, 1L);
  curl_easy_setopt(curl, CURLOPT_ERRORBUFFER, error);
  const CURLcode rc = curl_easy_perform(curl);
  if (rc != CURLE_OK) {
    result.error = error[0] ? error : curl_easy_strerror(rc);
  } else {
    curl_easy_getinfo(curl, CURLINFO_RESPONSE_CODE, &result.status);
  }
  curl_slist_free_all(headers);
  curl_easy_cleanup(curl);
  return result;
}

std::string DefaultCacheDir() {
  const char* home = std::getenv("HOME");
  return std::string(home && *home ? home : "/tmp") + "/.cache/motionpipe/llm";
}

class LlmLabeler : public Labeler {
 public:
  explicit LlmLabeler(const nlohmann::json& c)
      : endpoint_(c.value("endpoint", std::string("http://127.0.0.1:8000/v1"))),
        api_(c.value("api", std::string("completions"))),
        model_(c.value("model", std::string("gpt-3.5-turbo-instruct"))),
        key_env_(c.value("api_key_env", std::string("OPENAI_API_KEY"))),
        timeout_(c.value("timeout", 30.0)),
        retries_(c.value("retries", 4)),
        backoff_(c.value("backoff", 0.5)),
        temperature_(c.value("temperature", 0.0)),
        max_tokens_(c.value("max_tokens", 40)),
        cache_dir_(c.value("cache_dir", DefaultCacheDir())) {
    while (!endpoint_.empty() && endpoint_.back() == '/') endpoint_.pop_back();
  }

  std::string Name() const override { return "llm"; }

  Result<std::vector<PartSet>> Label(const std::vector<LabelInput>& inputs) override {
    MP_RETURN_IF_ERROR(MakeDirs(cache_dir_));
    std::vector<PartSet> out;
    out.reserve(inputs.size());
    for (const auto& input : inputs) {
      MP_ASSIGN_OR_RETURN(const std::string answer, Answer(input.text));
      out.push_back(PartsFromGptAnswer(answer));
    }
    return out;
  }

  int64_t requests() const { return requests_; }

 private:
  std::string CachePath(const std::string& text) const {
    return cache_dir_ + "/" + Sha256Hex(std::string(kPromptVersion) + "\n" + model_ + "\n" + text) +
           ".json";
  }

  Result<std::string> Answer(const std::string& text) {
    const std::string path = CachePath(text);
    if (auto cached = ReadFile(path); cached.ok()) {
      const nlohmann::json j = nlohmann::json::parse(*cached, nullptr, false);
      if (j.is_object() && j.value("text", std::string()) == text && j.contains("answer"))
        return j["answer"].get<std::string>();
    }
    const char* key = key_env_.empty() ? nullptr : std::getenv(key_env_.c_str());
    nlohmann::json request = {
        {"model", model_}, {"temperature", temperature_}, {"max_tokens", max_tokens_}};
    std::string url;
    if (api_ == "chat") {
      url = endpoint_ + "/chat/completions";
      request["messages"] = {{{"role", "user"}, {"content", SincPrompt(text)}}};
    } else {
      url = endpoint_ + "/completions";
      request["prompt"] = SincPrompt(text);
      request["stop"] = {"\nQ:", "\n\n"};
    }
    std::string last_error;
    double wait = backoff_;
    for (int attempt = 0; attempt <= retries_; ++attempt) {
      if (attempt > 0) {
        std::this_thread::sleep_for(std::chrono::duration<double>(wait));
        wait *= 2;
      }
      ++requests_;
      const HttpResult r = Post(url, request.dump(), key ? key : "", timeout_);
      if (!r.error.empty()) {
        last_error = r.error;
        continue;
      }
      if (r.status == 429 || r.status >= 500) {
        last_error = "HTTP " + std::to_string(r.status) + ": " + r.body.substr(0, 200);
        continue;
      }
      if (r.status != 200) {
        return InvalidArgument("llm labeler: " + url + " answered HTTP " +
                               std::to_string(r.status) + " for '" + text +
                               "': " + r.body.substr(0, 300));
      }
      const nlohmann::json j = nlohmann::json::parse(r.body, nullptr, false);
      std::string answer;
      try {
        const auto& choice = j.at("choices").at(0);
        answer = api_ == "chat" ? choice.at("message").at("content").get<std::string>()
                                : choice.at("text").get<std::string>();
      } catch (const nlohmann::json::exception&) {
        last_error = "unexpected response: " + r.body.substr(0, 200);
        continue;
      }
      const nlohmann::json entry = {
          {"text", text}, {"answer", answer}, {"model", model_}, {"prompt", kPromptVersion}};
      if (Status s = WriteFileAtomic(path, entry.dump() + "\n", false); !s.ok()) {
        MP_LOG(kWarn, "labels") << "llm labeler: cannot cache the answer: " << s.message();
      }
      return answer;
    }
    return IoError("llm labeler: " + url + " failed for '" + text + "' after " +
                   std::to_string(retries_ + 1) + " attempts: " + last_error);
  }

  std::string endpoint_, api_, model_, key_env_;
  double timeout_;
  int retries_;
  double backoff_, temperature_;
  int max_tokens_;
  std::string cache_dir_;
  int64_t requests_ = 0;
};

}  // namespace

std::string SincPrompt(const std::string& action) {
  return "Choose answers from the list ['left arm', 'right arm', 'left leg', 'buttocks', 'waist', "
         "'right leg', "
         "'torso', 'neck'].\n"
         "Q: What are the body parts involved in the action of: walk forwards?\n"
         "Answer: right leg\nleft leg\nbuttocks\n"
         "Q: What are the body parts involved in the action of: face to the left?\n"
         "Answer: torso\nneck\n"
         "Q: What are the body parts involved in the action of: put headphones over ears?\n"
         "Answer: right arm\nleft arm\nneck\n"
         "Q: What are the body parts involved in the action of: sit down?\n"
         "Answer: right leg\nleft leg\nbuttocks\nwaist\n"
         "Q: What are the body parts involved in the action of: " +
         action + "?\nAnswer:";
}

Result<std::unique_ptr<Labeler>> MakeLlmLabeler(const nlohmann::json& config) {
  const std::string api = config.value("api", std::string("completions"));
  if (api != "completions" && api != "chat")
    return InvalidArgument("llm labeler: api must be completions or chat");
  return std::unique_ptr<Labeler>(new LlmLabeler(config));
}

}  // namespace motionpipe::labels
