# Sources of the core's depth stage (included by CMakeLists.txt).
set(FM_DEPTH_SOURCES
  plane_sweep.cpp
  sweep_planes.cpp
  sweep_work.cpp
  plane_sweep_config.cpp
  depth_filters.cpp
  infinity_cost.cpp
  view_selection.cpp
  plane_sweep_cpu.cpp
  plane_sweep_cl.cpp
  plane_sweep_native.cpp
  depth_image.cpp
  depth_stage.cpp
)
