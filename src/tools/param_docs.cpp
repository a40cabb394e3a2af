// param_docs: prints docs/parameters.md, every nodelet's parameters from their
// declarations (ParamTable):
//   rosrun fisheye_mapping param_docs > docs/parameters.md
#include <iostream>

#include "cli.h"
#include "fisheye_mapping/ros/param_registry.h"

namespace fm = fisheye_mapping;

int main(int argc, char** argv) {
  const std::string usage =
      "usage: param_docs\n"
      "  Prints docs/parameters.md (every nodelet's parameters, from their declarations) on stdout.\n";
  const int rc = fm::cli::parseCommandLine("param_docs", usage, [&] {
    fm::cli::forEachOption(argc, argv, 1, [](const std::string&, const fm::cli::NextValue&) { return false; });
  });
  if (rc >= 0) return rc;
  std::cout << fm::parametersMarkdown();
  return 0;
}
