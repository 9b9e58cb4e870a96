// The simulated device's non-volatile store: a file of a fixed size named on its command
// line (--store FILE). Every write is on the disk before write() returns (pwrite, then
// fdatasync), so a SIGKILL of the simulator, or a power cut of the machine, after a record
// was appended loses nothing. Header-only, so the native tests use the same code.
#pragma once

#include <errno.h>
#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdint>
#include <cstring>
#include <string>

#include "graspguide_device/nv_storage.h"

namespace graspguide::sim {

class FileStorage final : public device::NvStorage {
 public:
  FileStorage() = default;
  FileStorage(const FileStorage&) = delete;
  FileStorage& operator=(const FileStorage&) = delete;
  ~FileStorage() { close(); }

  // Opens path as a store of size_bytes: creates it filled with 0xFF (erased) when missing,
  // extends a shorter file with 0xFF, and refuses a longer one or one another process has
  // open as its store. false with *error saying what is wrong and what to do (without the
  // path: the caller's message names it).
  bool open(const char* path, uint32_t size_bytes, std::string* error) {
    close();
    const std::string p = path ? path : "";
    const auto fail = [&](const std::string& why) {
      if (error) *error = why;  // the caller names the file (it is on its command line)
      close();
      return false;
    };
    if (p.empty()) return fail("no file named");
    fd_ = ::open(p.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd_ < 0) return fail(std::string("cannot open: ") + std::strerror(errno));
    // Two simulators appending to one file would interleave their records.
    if (::flock(fd_, LOCK_EX | LOCK_NB) != 0)
      return fail("already in use by another process (one store per simulated device)");
    struct stat st;
    if (::fstat(fd_, &st) != 0) return fail(std::string("cannot stat: ") + std::strerror(errno));
    if (!S_ISREG(st.st_mode)) return fail("not a regular file");
    const uint64_t have = static_cast<uint64_t>(st.st_size);
    if (have > size_bytes)
      return fail("is " + std::to_string(have) + " bytes, but this device's store is " +
                  std::to_string(size_bytes) +
                  " bytes: it belongs to another build or was not made by the simulator; name "
                  "another file, or delete it to start empty");
    if (have < size_bytes) {
      uint8_t ff[4096];
      std::memset(ff, 0xFF, sizeof ff);
      for (uint64_t at = have; at < size_bytes;) {
        const uint64_t n = size_bytes - at < sizeof ff ? size_bytes - at : sizeof ff;
        if (!write_all(static_cast<off_t>(at), ff, static_cast<size_t>(n)))
          return fail(std::string("cannot fill with 0xFF: ") + std::strerror(errno));
        at += n;
      }
      if (::fsync(fd_) != 0) return fail(std::string("cannot sync: ") + std::strerror(errno));
      if (!sync_directory(p))
        return fail(std::string("cannot sync its directory: ") + std::strerror(errno));
    }
    size_ = size_bytes;
    return true;
  }

  void close() {
    if (fd_ >= 0) ::close(fd_);  // also drops the flock
    fd_ = -1;
    size_ = 0;
  }
  bool is_open() const { return fd_ >= 0; }

  uint32_t size_bytes() const override { return size_; }

  bool read(uint32_t offset, uint8_t* out, uint32_t n) override {
    if (fd_ < 0 || !device::nv_range_ok(size_, offset, n)) return false;
    size_t done = 0;
    while (done < n) {
      const ssize_t r = ::pread(fd_, out + done, n - done, static_cast<off_t>(offset + done));
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) return false;
      done += static_cast<size_t>(r);
    }
    return true;
  }

  bool write(uint32_t offset, const uint8_t* data, uint32_t n) override {
    if (fd_ < 0 || !device::nv_range_ok(size_, offset, n)) return false;
    if (!write_all(static_cast<off_t>(offset), data, n)) return false;
    // Data only: the file's size never changes after open(), so its metadata needs no sync.
    while (::fdatasync(fd_) != 0)
      if (errno != EINTR) return false;
    return true;
  }

 private:
  bool write_all(off_t offset, const uint8_t* data, size_t n) {
    size_t done = 0;
    while (done < n) {
      const ssize_t w = ::pwrite(fd_, data + done, n - done, offset + static_cast<off_t>(done));
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) return false;
      done += static_cast<size_t>(w);
    }
    return true;
  }

  // A new file's directory entry must reach the disk too, or a power cut could lose the file.
  static bool sync_directory(const std::string& path) {
    const size_t slash = path.rfind('/');
    const std::string dir = slash == std::string::npos ? "."
                            : slash == 0               ? "/"
                                                       : path.substr(0, slash);
    const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (dfd < 0) return false;
    const bool ok = ::fsync(dfd) == 0;
    ::close(dfd);
    return ok;
  }

  int fd_ = -1;
  uint32_t size_ = 0;
};

}  // namespace graspguide::sim
