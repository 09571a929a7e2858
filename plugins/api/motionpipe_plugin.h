/* motionpipe plugin ABI: the one C boundary between the host (worker, CLI) and a plugin library.
 *
 * A plugin is a shared library exporting one symbol, MOTIONPIPE_PLUGIN_ENTRY, a function returning
 * a static mp_plugin. The host loads it with RTLD_LOCAL, checks abi_version before touching
 * anything else (a mismatch is reported, never called), and never unloads it (unloading LibTorch
 * code crashes). Host and plugins link the same shared LibTorch; C++ interfaces for model objects
 * (plugins/api/plugin.hpp) sit on top of the factories below.
 */
#ifndef MOTIONPIPE_PLUGIN_H_
#define MOTIONPIPE_PLUGIN_H_

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define MOTIONPIPE_PLUGIN_ABI_VERSION 2u
#define MOTIONPIPE_PLUGIN_ENTRY "motionpipe_plugin_v1"

enum mp_task_outcome { MP_TASK_OK = 0, MP_TASK_ERROR = 1, MP_TASK_BAD_INPUT = 2 };
enum mp_log_level { MP_LOG_DEBUG = 0, MP_LOG_INFO = 1, MP_LOG_WARN = 2, MP_LOG_ERROR = 3 };

/* What a task sees. task_json holds the TaskSpec: job_id, job_name, stage, kind, index, count,
 * reduce, params (object), output_dir (write outputs there; the host checksums every file in it),
 * inputs
 * ([{stage, dirs, result_dir}]), seed, threads, attempt; for gangs (world_size > 1, index = rank)
 * the rendezvous (a c10d FileStore path shared by the ranks); state_dir survives attempts
 * (checkpoints). */
typedef struct mp_task_io {
  const char* task_json;
  const volatile int* cancel; /* becomes non-zero when the task should stop early */
  void* host;
  void (*report_metric)(void* host, const char* name, double value);
  void (*log)(void* host, int level, const char* message);
  /* ABI 2: an object factory of any loaded plugin (e.g. the `train` stage finds kind "model"), or
   * NULL. */
  const struct mp_object_factory* (*find_factory)(void* host, const char* kind, const char* name);
} mp_task_io;

/* Runs one task; returns an mp_task_outcome and, on failure, a message in error[error_size]. */
typedef int (*mp_run_task_fn)(const mp_task_io* io, char* error, size_t error_size);

typedef struct mp_stage_kind {
  const char* kind; /* pipeline `kind:` value, e.g. "sample.checksum" */
  const char* description;
  mp_run_task_fn run;
} mp_stage_kind;

/* Objects other parts of motionpipe use: kind "model", "text_encoder" or "labeler". create()
 * returns an object implementing the matching C++ interface of plugins/api/plugin.hpp (or NULL with
 * error). */
struct mp_object_factory {
  const char* kind;
  const char* name;
  void* (*create)(const char* config_json, char* error, size_t error_size);
  void (*destroy)(void* object);
};
typedef struct mp_object_factory mp_object_factory;

typedef struct mp_plugin {
  uint32_t abi_version; /* MOTIONPIPE_PLUGIN_ABI_VERSION, checked first */
  uint32_t struct_size; /* sizeof(mp_plugin) as the plugin was compiled */
  const char* name;
  const char* version;
  uint32_t num_stage_kinds;
  const mp_stage_kind* stage_kinds;
  uint32_t num_factories;
  const mp_object_factory* factories;
} mp_plugin;

typedef const mp_plugin* (*mp_plugin_entry_fn)(void);

#ifdef __cplusplus
}
#endif

#endif /* MOTIONPIPE_PLUGIN_H_ */
