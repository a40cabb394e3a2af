# Sources of the core's sim stage (included by CMakeLists.txt).
set(FM_SIM_SOURCES
  synthetic_world.cpp
  vehicle_labels.cpp
  vehicle_model.cpp
)
