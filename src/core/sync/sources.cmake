# Sources of the core's sync stage (included by CMakeLists.txt).
set(FM_SYNC_SOURCES
  frame_pacer.cpp
  frame_sync.cpp
  sync_report.cpp
)
