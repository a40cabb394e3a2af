# Sources of the core's mapping stage (included by CMakeLists.txt).
set(FM_MAPPING_SOURCES
  frame_set_mapper.cpp
)
