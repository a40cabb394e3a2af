// Shared by the command-line tools (header-only, no ROS): strict parsing of
// option values, checks of input files and output folders, and outputs written
// under a temporary name and renamed over the old file only once complete.
//
// Every check throws cli::UsageError whose message names the option and the bad
// value, e.g. "--frames needs a whole number, got 'abc'" or
// "--every must lie in [1, 1000000], got -3"; a tool prints it after its own
// name and exits 2.
//
// Every tool parses its command line the same way (parseCommandLine around
// forEachOption): -h / --help prints the full usage on stdout and exits 0; an
// unknown option ("unknown option '--foo'"), a missing value ("--frames needs a
// value") or a bad value prints the error and the usage on stderr and exits 2.
#ifndef FISHEYE_MAPPING_SRC_TOOLS_CLI_H_
#define FISHEYE_MAPPING_SRC_TOOLS_CLI_H_

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <system_error>
#include <vector>

#include <unistd.h>

#include "fisheye_mapping/core/common/safe_open.h"
#include "fisheye_mapping/core/common/safe_write.h"

namespace fisheye_mapping {
namespace cli {

class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// -h / --help on the command line: thrown by forEachOption, turned into the
// usage on stdout and exit status 0 by parseCommandLine.
struct HelpRequested {};

// Consumes and returns the value of the option being handled.
using NextValue = std::function<std::string()>;

// A tool whose stages run concurrently on the same cores (offline_mapper)
// wants idle OpenMP threads to sleep rather than spin, or one stage's waiting
// threads take CPU from the others (docs/benchmarks.md). libgomp reads
// OMP_WAIT_POLICY only when it is loaded, so when the variable is unset this
// sets it to passive and runs the tool again in the same process (exec, once:
// the variable is set then). A user's own OMP_WAIT_POLICY is kept; if the exec
// fails the tool goes on as it is.
inline void rerunWithPassiveOpenMpWait(char** argv) {
  if (std::getenv("OMP_WAIT_POLICY") != nullptr) return;
  if (setenv("OMP_WAIT_POLICY", "passive", 1) != 0) return;
  execv("/proc/self/exe", argv);
}

// The option loop of the tools. Walks argv[first..argc): -h / --help throws
// HelpRequested; any other argument goes to handle(arg, next), where next()
// consumes the argument after it (UsageError "<arg> needs a value" when there is
// none). handle returns false for an argument it does not take: one that starts
// with '-' is an unknown option, any other an unexpected argument.
inline void forEachOption(int argc, char** argv, int first,
                          const std::function<bool(const std::string& arg, const NextValue& next)>& handle) {
  for (int i = first; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "-h" || a == "--help") throw HelpRequested{};
    const NextValue next = [&]() -> std::string {
      if (i + 1 >= argc) throw UsageError(a + " needs a value");
      return argv[++i];
    };
    if (handle(a, next)) continue;
    if (a.size() > 1 && a[0] == '-') throw UsageError("unknown option '" + a + "'");
    throw UsageError("unexpected argument '" + a + "'");
  }
}

// Runs a tool's parsing and checking of its options, `parse`. Returns 0 after
// printing `usage` on stdout when help was asked for; 2 after printing
// "<tool>: <error>" and the usage on stderr on a UsageError; -1 when the tool
// goes on.
inline int parseCommandLine(const std::string& tool, const std::string& usage, const std::function<void()>& parse) {
  try {
    parse();
  } catch (const HelpRequested&) {
    std::cout << usage;
    return 0;
  } catch (const UsageError& e) {
    std::cerr << tool << ": " << e.what() << "\n" << usage;
    return 2;
  }
  return -1;
}

// Shortest text of a number that reads back the same ("1e+06" -> "1000000").
inline std::string numberText(double v) {
  std::ostringstream s;
  s.precision(15);
  s << v;
  return s.str();
}

// A whole number in [lo, hi]: decimal digits with an optional sign, nothing
// else (no "12abc", "1.5", " 7", "0x10", empty text).
inline long long parseInt(const std::string& option, const std::string& text, long long lo, long long hi) {
  const auto bad = [&]() { return UsageError(option + " needs a whole number, got '" + text + "'"); };
  if (text.empty() || text.size() > 40) throw bad();
  size_t i = (text[0] == '-' || text[0] == '+') ? 1 : 0;
  if (i == text.size()) throw bad();
  for (size_t k = i; k < text.size(); ++k) {
    if (text[k] < '0' || text[k] > '9') throw bad();
  }
  errno = 0;
  char* end = nullptr;
  const long long v = std::strtoll(text.c_str(), &end, 10);
  if (errno == ERANGE || v < lo || v > hi) {
    throw UsageError(option + " must lie in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got " + text);
  }
  return v;
}

// A finite decimal number (decimal or exponent notation: no "nan", "inf",
// trailing text or hexadecimal such as 0x10, which strtod alone accepts):
// the tools' one number syntax, for options and for rig_info's input lines.
// False when `text` is not one; *out_of_range when it overflows.
inline bool parseDecimal(const std::string& text, double* v, bool* out_of_range = nullptr) {
  if (out_of_range) *out_of_range = false;
  if (text.empty() || text.size() > 64) return false;
  for (char c : text) {
    if (!((c >= '0' && c <= '9') || c == '.' || c == '-' || c == '+' || c == 'e' || c == 'E')) return false;
  }
  errno = 0;
  char* end = nullptr;
  *v = std::strtod(text.c_str(), &end);
  if (end == text.c_str() || *end != '\0') return false;
  if (!std::isfinite(*v) || errno == ERANGE) {
    if (out_of_range) *out_of_range = true;
    return false;
  }
  return true;
}

// A finite number in [lo, hi] (parseDecimal's syntax).
inline double parseDouble(const std::string& option, const std::string& text, double lo, double hi) {
  double v = 0;
  bool out_of_range = false;
  if (!parseDecimal(text, &v, &out_of_range) && !out_of_range)
    throw UsageError(option + " needs a number, got '" + text + "'");
  if (out_of_range || v < lo || v > hi) {
    throw UsageError(option + " must lie in [" + numberText(lo) + ", " + numberText(hi) + "], got " + text);
  }
  return v;
}

// A number in (0, hi]: positive, finite.
inline double parsePositive(const std::string& option, const std::string& text, double hi) {
  const double v = parseDouble(option, text, -std::numeric_limits<double>::max(), hi);
  if (!(v > 0.0)) throw UsageError(option + " must be positive, got " + text);
  return v;
}

// NAME=VALUE (--set, --image, --topic ...): the name before the first '=',
// not empty; the value after it.
inline std::pair<std::string, std::string> parseNameValue(const std::string& option, const std::string& text) {
  const size_t eq = text.find('=');
  if (eq == std::string::npos || eq == 0) throw UsageError(option + " expects NAME=VALUE, got '" + text + "'");
  return {text.substr(0, eq), text.substr(eq + 1)};
}

// Comma-separated numbers, each in [lo, hi]; at least one, at most max_count.
inline std::vector<double> parseDoubleList(const std::string& option, const std::string& text, double lo, double hi,
                                           size_t max_count = 100) {
  std::vector<double> out;
  if (text.empty()) throw UsageError(option + " needs a comma-separated list of numbers, got ''");
  std::string item;
  std::stringstream ss(text);
  while (std::getline(ss, item, ',')) {
    if (out.size() == max_count) {
      throw UsageError(option + " takes at most " + std::to_string(max_count) + " values");
    }
    out.push_back(parseDouble(option, item, lo, hi));
  }
  if (!text.empty() && text.back() == ',') throw UsageError(option + " needs a number, got ''");
  return out;
}

// "WxH" with both in [1, max_side].
inline void parseSize(const std::string& option, const std::string& text, int max_side, int* w, int* h) {
  const size_t x = text.find('x');
  if (x == std::string::npos) throw UsageError(option + " needs WxH (e.g. 1280x800), got '" + text + "'");
  try {
    *w = static_cast<int>(parseInt(option, text.substr(0, x), 1, max_side));
    *h = static_cast<int>(parseInt(option, text.substr(x + 1), 1, max_side));
  } catch (const UsageError&) {
    throw UsageError(option + " needs WxH with each side in [1, " + std::to_string(max_side) + "] pixels, got '" +
                     text + "'");
  }
}

// An input file: exists, is not a directory, can be opened for reading.
inline void requireInputFile(const std::string& option, const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (path.empty()) throw UsageError(option + " needs a file name, got ''");
  const fs::file_status st = fs::status(path, ec);
  if (ec || !fs::exists(st)) throw UsageError(option + ": " + path + ": no such file");
  if (fs::is_directory(st)) throw UsageError(option + ": " + path + " is a directory, expected a file");
  // Opened without blocking: a FIFO or a device is refused at once.
  const std::string why = regularFileProblem(path, kNoSizeLimit);
  if (why.rfind("cannot open", 0) == 0) throw UsageError(option + ": " + path + ": cannot open for reading");
  if (!why.empty()) throw UsageError(option + ": " + path + " " + why);
}

// An output folder: created when missing (with its parents); an existing path
// that is not a folder is an error, as is a folder we cannot write into.
inline void prepareOutputDir(const std::string& option, const std::string& path) {
  namespace fs = std::filesystem;
  if (path.empty()) throw UsageError(option + " needs a folder name, got ''");
  std::error_code ec;
  if (fs::exists(path, ec) && !fs::is_directory(path, ec)) {
    throw UsageError(option + ": " + path + " exists and is not a folder");
  }
  fs::create_directories(path, ec);
  if (ec) throw UsageError(option + ": cannot create folder " + path + ": " + ec.message());
  if (access(path.c_str(), W_OK) != 0) throw UsageError(option + ": cannot write into folder " + path);
}

// An output file: its folder must exist (nothing is created), the path must not
// be a folder.
inline void requireOutputFile(const std::string& option, const std::string& path) {
  namespace fs = std::filesystem;
  if (path.empty()) throw UsageError(option + " needs a file name, got ''");
  std::error_code ec;
  if (fs::is_directory(path, ec)) throw UsageError(option + ": " + path + " is a directory, expected a file");
  const fs::path parent = fs::path(path).parent_path();
  if (!parent.empty() && !fs::is_directory(parent, ec)) {
    throw UsageError(option + ": " + path + ": no such folder " + parent.string());
  }
  if (access(parent.empty() ? "." : parent.c_str(), W_OK) != 0) {
    throw UsageError(option + ": " + path + ": cannot write into folder " +
                     (parent.empty() ? std::string(".") : parent.string()));
  }
}

// Writes the text `fill` puts into the stream to `path` through
// writeFileSafely (core/common/safe_write.h): complete or not at all (a
// failed write keeps the old file and leaves no temporary), a link at path
// replaced, never followed, a FIFO or a device refused, fsync, size and close
// checked. Throws std::runtime_error naming the file and the OS error.
inline void writeTextAtomically(const std::string& path, const std::function<void(std::ostream&)>& fill) {
  std::ostringstream text;
  fill(text);
  writeFileSafely(path, text.str());
}

}  // namespace cli
}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_SRC_TOOLS_CLI_H_
