// Runs a command line (a tool under test) and keeps its output (stdout and
// stderr together) and exit status; a signal gives 128 + its number.
#ifndef FISHEYE_MAPPING_TEST_TOOL_RUN_H_
#define FISHEYE_MAPPING_TEST_TOOL_RUN_H_

#include <sys/wait.h>

#include <cstdio>
#include <string>

namespace fisheye_mapping {
namespace test {

struct ToolRun {
  std::string out;
  int status;
};

inline ToolRun runTool(const std::string& cmd) {
  ToolRun r{"", -1};
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  if (!p) return r;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), p)) > 0) r.out.append(buf, n);
  const int st = pclose(p);
  r.status = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
  return r;
}

}  // namespace test
}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_TEST_TOOL_RUN_H_
