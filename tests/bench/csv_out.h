// csv_out.h: the machine-readable side of the bench programs. `--out DIR` makes a program write each of its tables
// as DIR/<name>.csv (a header line with units in the column names, then printf-formatted rows) next to the readable
// tables it prints; scripts/report/ turns them into the report's tables and plots.
#pragma once
#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <string>

namespace surgsim::bench {

class CsvOut {
 public:
  CsvOut() = default;
  /// Opens DIR/NAME.csv and writes the header; an empty dir makes every call a no-op (no --out given). With `append`,
  /// rows go after those already in the file (several runs, one table) and the header is written only to a new file.
  CsvOut(const std::string& dir, const std::string& name, const char* header, bool append = false) {
    if (dir.empty()) return;
    path_ = dir + "/" + name + ".csv";
    std::FILE* existing = append ? std::fopen(path_.c_str(), "r") : nullptr;
    if (existing) std::fclose(existing);
    file_ = std::fopen(path_.c_str(), append ? "a" : "w");
    if (!file_)
      throw std::runtime_error(path_ + ": cannot write: " + std::strerror(errno) + " (check that --out names a writable folder)");
    if (!existing) std::fprintf(file_, "%s\n", header);
  }
  CsvOut(const CsvOut&) = delete;
  CsvOut& operator=(const CsvOut&) = delete;
  CsvOut(CsvOut&& o) noexcept : file_(o.file_), path_(std::move(o.path_)) { o.file_ = nullptr; }
  CsvOut& operator=(CsvOut&& o) noexcept {
    if (this != &o) {
      close();
      file_ = o.file_;
      path_ = std::move(o.path_);
      o.file_ = nullptr;
    }
    return *this;
  }
  ~CsvOut() { close(); }

  /// One row, printf-style, without the newline.
  __attribute__((format(printf, 2, 3))) void row(const char* format, ...) {
    if (!file_) return;
    va_list args;
    va_start(args, format);
    std::vfprintf(file_, format, args);
    va_end(args);
    std::fputc('\n', file_);
    std::fflush(file_);
  }

 private:
  void close() {
    if (file_) std::fclose(file_);
    file_ = nullptr;
  }
  std::FILE* file_ = nullptr;
  std::string path_;
};

}  // namespace surgsim::bench
