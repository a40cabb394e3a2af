# Sources of the core's tsdf stage (included by CMakeLists.txt).
set(FM_TSDF_SOURCES
  tsdf_config.cpp
  block_store.cpp
  tsdf_integrator.cpp
  tsdf_integrator_cpu.cpp
  tsdf_integrator_cl.cpp
  tsdf_io.cpp
  tsdf_map.cpp
  tsdf_mesher.cpp
  map_session.cpp
  occupancy_grid.cpp
  fusion_stage.cpp
)
