# Sources of the core's detection stage (included by CMakeLists.txt).
set(FM_DETECTION_SOURCES
  detector.cpp
  detector_registry.cpp
  held_depth.cpp
  depth_mask.cpp
  mask_decisions.cpp
  vehicle_motion.cpp
)
