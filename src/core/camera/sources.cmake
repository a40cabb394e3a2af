# Sources of the core's camera stage (included by CMakeLists.txt).
set(FM_CAMERA_SOURCES
  camera_model.cpp
  rig_calibration.cpp
  rig_geometry.cpp
  online_calibration.cpp
  rig_refinement.cpp
)
