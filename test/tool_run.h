// Runs a command line (a tool under test) and keeps its output (stdout and
// stderr together, or apart with runToolApart) and exit status; a signal gives
// 128 + its number.
#ifndef FISHEYE_MAPPING_TEST_TOOL_RUN_H_
#define FISHEYE_MAPPING_TEST_TOOL_RUN_H_

#include <sys/wait.h>

#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>

namespace fisheye_mapping {
namespace test {

struct ToolRun {
  std::string out;
  int status;
};

// `cmd` with its stdout read here (its stderr as `cmd` redirects it).
inline ToolRun runRaw(const std::string& cmd) {
  ToolRun r{"", -1};
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return r;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), p)) > 0) r.out.append(buf, n);
  const int st = pclose(p);
  r.status = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
  return r;
}

inline ToolRun runTool(const std::string& cmd) { return runRaw(cmd + " 2>&1"); }

struct ToolRunApart {
  std::string out, err;
  int status;
};

// Stdout and stderr kept apart (stderr through a temporary file).
inline ToolRunApart runToolApart(const std::string& cmd) {
  static int calls = 0;
  const std::string err_file =
      "/tmp/fm_tool_run_" + std::to_string(getpid()) + "_" + std::to_string(calls++) + ".stderr";
  const ToolRun r = runRaw(cmd + " 2>" + err_file);
  std::ifstream f(err_file);
  std::stringstream err;
  err << f.rdbuf();
  std::remove(err_file.c_str());
  return {r.out, err.str(), r.status};
}

}  // namespace test
}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_TEST_TOOL_RUN_H_
