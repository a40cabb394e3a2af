# Sources of the core's eval stage (included by CMakeLists.txt).
set(FM_EVAL_SOURCES
  mesh_distance.cpp
  depth_consistency.cpp
  depth_error.cpp
)
