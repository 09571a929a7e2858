// A fault-injecting filesystem shim for the disk-fault tests (LD_PRELOAD), in the spirit of
// LevelDB's fault-injection Env: while the file named by FAULTFS_TRIGGER exists, the write and
// sync calls of this process on files under FAULTFS_PREFIX fail with FAULTFS_ERRNO (ENOSPC, EIO,
// ...), as a full or failing disk makes them fail. Removing the trigger file is "space returns".
//   FAULTFS_PREFIX   absolute path prefix of the files affected (required)
//   FAULTFS_TRIGGER  file whose existence turns the faults on (required)
//   FAULTFS_ERRNO    errno name: ENOSPC (default) or EIO
//   FAULTFS_OPS      comma-separated: write (write, pwrite, writev, ftruncate, fallocate), sync
//                    (fsync, fdatasync); default both
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>
#include <sys/uio.h>
#include <unistd.h>

static int Affected(int fd, const char* op) {
  const char* prefix = getenv("FAULTFS_PREFIX");
  const char* trigger = getenv("FAULTFS_TRIGGER");
  if (!prefix || !trigger || access(trigger, F_OK) != 0) return 0;
  const char* ops = getenv("FAULTFS_OPS");
  if (ops && !strstr(ops, op)) return 0;
  char link[64], path[4096];
  snprintf(link, sizeof(link), "/proc/self/fd/%d", fd);
  const ssize_t n = readlink(link, path, sizeof(path) - 1);
  if (n <= 0) return 0;
  path[n] = '\0';
  if (strncmp(path, prefix, strlen(prefix)) != 0) return 0;
  const char* name = getenv("FAULTFS_ERRNO");
  errno = (name && strcmp(name, "EIO") == 0) ? EIO : ENOSPC;
  return 1;
}

#define NEXT(name) ((__typeof__(&name))dlsym(RTLD_NEXT, #name))

ssize_t write(int fd, const void* buf, size_t count) {
  if (Affected(fd, "write")) return -1;
  return NEXT(write)(fd, buf, count);
}

ssize_t pwrite(int fd, const void* buf, size_t count, off_t offset) {
  if (Affected(fd, "write")) return -1;
  return NEXT(pwrite)(fd, buf, count, offset);
}

ssize_t pwrite64(int fd, const void* buf, size_t count, off64_t offset) {
  if (Affected(fd, "write")) return -1;
  return NEXT(pwrite64)(fd, buf, count, offset);
}

ssize_t writev(int fd, const struct iovec* iov, int iovcnt) {
  if (Affected(fd, "write")) return -1;
  return NEXT(writev)(fd, iov, iovcnt);
}

int ftruncate(int fd, off_t length) {
  if (Affected(fd, "write")) return -1;
  return NEXT(ftruncate)(fd, length);
}

int ftruncate64(int fd, off64_t length) {
  if (Affected(fd, "write")) return -1;
  return NEXT(ftruncate64)(fd, length);
}

int fallocate(int fd, int mode, off_t offset, off_t len) {
  if (Affected(fd, "write")) return -1;
  return NEXT(fallocate)(fd, mode, offset, len);
}

int posix_fallocate(int fd, off_t offset, off_t len) {
  if (Affected(fd, "write")) return errno;  // posix_fallocate returns the error number
  return NEXT(posix_fallocate)(fd, offset, len);
}

int fsync(int fd) {
  if (Affected(fd, "sync")) return -1;
  return NEXT(fsync)(fd);
}

int fdatasync(int fd) {
  if (Affected(fd, "sync")) return -1;
  return NEXT(fdatasync)(fd);
}
