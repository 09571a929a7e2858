// Body-part labels from a language model behind an OpenAI-compatible HTTP API (/v1/completions or
// /v1/chat/completions: OpenAI, vLLM, llama.cpp's server, ...), with SINC's prompt: the list of
// parts to choose from, four few-shot examples, then the question (REFERENCE 4.1). Answers are
// mapped with PartsFromGptAnswer and cached on disk, one file per text, so a text is asked once
// across runs and workers.
//
// Config: endpoint (base URL, default http://127.0.0.1:8000/v1), api ("completions" | "chat"),
// model, api_key_env (name of the environment variable holding the key, default OPENAI_API_KEY),
// timeout (seconds per request, 30), retries (4; backoff 0.5 s doubling; 429 and 5xx are retried,
// other 4xx are not), temperature (0), max_tokens (40), cache_dir (default
// ~/.cache/motionpipe/llm).
#pragma once

#include <memory>
#include <string>

#include "motionpipe/labels/labeler.h"

namespace motionpipe::labels {

// The completion prompt for one action text.
std::string SincPrompt(const std::string& action);

Result<std::unique_ptr<Labeler>> MakeLlmLabeler(const nlohmann::json& config);

}  // namespace motionpipe::labels
