# Sources of the core's tsdf stage (included by CMakeLists.txt).
set(FM_TSDF_SOURCES
  tsdf_map.cpp
  tsdf_mesher.cpp
  tsdf_integrator_cl.cpp
  tsdf_io.cpp
)
