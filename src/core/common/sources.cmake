# Sources of the core's common stage (included by CMakeLists.txt).
set(FM_COMMON_SOURCES
  cpu_features.cpp
  opencl_context.cpp
  param_table.cpp
  paths.cpp
  safe_open.cpp
  safe_write.cpp
  stage_stats.cpp
)
