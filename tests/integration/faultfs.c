// A fault-injecting filesystem shim for the disk-fault tests (LD_PRELOAD), in the spirit of
// LevelDB's fault-injection Env: while the file named by FAULTFS_TRIGGER exists, the write and
// sync calls of this process on files under FAULTFS_PREFIX fail with FAULTFS_ERRNO (ENOSPC, EIO,
// ...), as a full or failing disk makes them fail. Removing the trigger file is "space returns".
//   FAULTFS_PREFIX   absolute path prefix of the files affected (required)
//   FAULTFS_TRIGGER  file whose existence turns the faults on (required)
//   FAULTFS_ERRNO    errno name: ENOSPC (default) or EIO
//   FAULTFS_OPS      comma-separated: write (write, pwrite, writev, ftruncate, fallocate), sync
//                    (fsync, fdatasync); default both
// Power-loss mode (LevelDB's FaultInjectionTestEnv keeps the same books): with FAULTFS_LOG set,
// every successful fsync or fdatasync of this process under FAULTFS_PREFIX appends to that log
// what it made durable. A regular file's content is copied to FAULTFS_LOG.blobs/ and logged as
//   F <inode> <blob>
// and a directory's entries (what a directory fsync makes durable) as
//   D <inode> <count>, then per entry: <inode> <d|f> <name>
// one record per write(2) with O_APPEND, so processes may share the log. powerloss.py rebuilds
// from it the tree a power loss would leave: names only where their directory was synced after
// they appeared, contents only as of their file's last sync.
#define _GNU_SOURCE
#include <dirent.h>
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
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

// The path of fd if it lies under FAULTFS_PREFIX and FAULTFS_LOG is set, else 0.
static int LoggedPath(int fd, char* path, size_t size) {
  const char* prefix = getenv("FAULTFS_PREFIX");
  if (!prefix || !getenv("FAULTFS_LOG")) return 0;
  char link[64];
  snprintf(link, sizeof(link), "/proc/self/fd/%d", fd);
  const ssize_t n = readlink(link, path, size - 1);
  if (n <= 0) return 0;
  path[n] = '\0';
  return strncmp(path, prefix, strlen(prefix)) == 0;
}

// Appends one record to the log in one write, so that concurrent processes do not interleave.
static void Append(const char* text, size_t length) {
  const int log = open(getenv("FAULTFS_LOG"), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (log < 0) return;
  NEXT(write)(log, text, length);
  close(log);
}

static void LogDirectory(const char* path, ino_t inode) {
  DIR* dir = opendir(path);
  if (!dir) return;
  size_t capacity = 4096, length = 0, count = 0;
  char* entries = malloc(capacity);
  struct dirent* e;
  while (entries && (e = readdir(dir)) != NULL) {
    if (strcmp(e->d_name, ".") == 0 || strcmp(e->d_name, "..") == 0) continue;
    int is_dir = e->d_type == DT_DIR;
    if (e->d_type == DT_UNKNOWN) {
      struct stat st;
      is_dir = fstatat(dirfd(dir), e->d_name, &st, AT_SYMLINK_NOFOLLOW) == 0 && S_ISDIR(st.st_mode);
    }
    if (length + strlen(e->d_name) + 64 > capacity) {
      capacity = 2 * capacity + strlen(e->d_name);
      entries = realloc(entries, capacity);
      if (!entries) break;
    }
    length += (size_t)snprintf(entries + length, capacity - length, "%llu %c %s\n",
                               (unsigned long long)e->d_ino, is_dir ? 'd' : 'f', e->d_name);
    ++count;
  }
  closedir(dir);
  if (!entries) return;
  char* record = malloc(length + 64);
  if (record) {
    const int head = snprintf(record, 64, "D %llu %zu\n", (unsigned long long)inode, count);
    memcpy(record + head, entries, length);
    Append(record, (size_t)head + length);
    free(record);
  }
  free(entries);
}

static void LogFile(int fd, ino_t inode) {
  static unsigned long counter = 0;
  char blob[4096], line[4200], link[64];
  snprintf(blob, sizeof(blob), "%s.blobs", getenv("FAULTFS_LOG"));
  mkdir(blob, 0755);
  snprintf(blob, sizeof(blob), "%s.blobs/%ld-%lu", getenv("FAULTFS_LOG"), (long)getpid(),
           ++counter);
  snprintf(link, sizeof(link), "/proc/self/fd/%d", fd);
  const int in = open(link, O_RDONLY | O_CLOEXEC);
  const int out = open(blob, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (in >= 0 && out >= 0) {
    char buffer[65536];
    ssize_t n;
    while ((n = read(in, buffer, sizeof(buffer))) > 0) NEXT(write)(out, buffer, (size_t)n);
  }
  if (in >= 0) close(in);
  if (out >= 0) close(out);
  const int length = snprintf(line, sizeof(line), "F %llu %s\n", (unsigned long long)inode,
                              strrchr(blob, '/') + 1);
  Append(line, (size_t)length);
}

// After a successful sync: what it made durable, in power-loss mode.
static void Synced(int fd) {
  char path[4096];
  struct stat st;
  if (!LoggedPath(fd, path, sizeof(path)) || fstat(fd, &st) != 0) return;
  const int saved = errno;
  if (S_ISDIR(st.st_mode)) {
    LogDirectory(path, st.st_ino);
  } else if (S_ISREG(st.st_mode)) {
    LogFile(fd, st.st_ino);
  }
  errno = saved;
}

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
  const int rc = NEXT(fsync)(fd);
  if (rc == 0) Synced(fd);
  return rc;
}

int fdatasync(int fd) {
  if (Affected(fd, "sync")) return -1;
  const int rc = NEXT(fdatasync)(fd);
  if (rc == 0) Synced(fd);
  return rc;
}
