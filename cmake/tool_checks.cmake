# Command-line tools that never crash, hang or lie: tests of their option
# parsing (src/tools/cli.h), of the inputs they reject, and the regression
# inputs of the fuzz targets (test/fuzz/<target>/, built with clang by
# scripts/fuzz) replayed through the same entry points with the normal build.
# Included at the end of CMakeLists.txt.

if(CATKIN_ENABLE_TESTING)
  catkin_add_gtest(test_map_accuracy test/test_map_accuracy.cpp)
  target_link_libraries(test_map_accuracy fisheye_mapping_core GTest::gtest_main)
  add_dependencies(test_map_accuracy map_accuracy)
  target_compile_definitions(test_map_accuracy PRIVATE FM_MAP_ACCURACY="$<TARGET_FILE:map_accuracy>")

  catkin_add_gtest(test_tool_options test/test_tool_options.cpp)
  target_link_libraries(test_tool_options fisheye_mapping_core GTest::gtest_main)
  target_include_directories(test_tool_options PRIVATE ${PROJECT_SOURCE_DIR}/src/tools)
  add_dependencies(test_tool_options tsdf_benchmark depth_benchmark detector_benchmark detect_image)
  target_compile_definitions(test_tool_options PRIVATE
    FM_TSDF_BENCHMARK="$<TARGET_FILE:tsdf_benchmark>" FM_DEPTH_BENCHMARK="$<TARGET_FILE:depth_benchmark>"
    FM_DETECTOR_BENCHMARK="$<TARGET_FILE:detector_benchmark>" FM_DETECT_IMAGE="$<TARGET_FILE:detect_image>"
    FM_TEST_DATA_DIR="${FM_TEST_DATA_DIR}" FM_CONFIG_DIR="${PROJECT_SOURCE_DIR}/config")

  # The fuzz targets themselves, entry points renamed (scripts/fuzz builds
  # them with clang and libFuzzer).
  set(FM_FUZZ_TARGETS rig_yaml:fmFuzzRigYaml psl_calib:fmFuzzPslCalib tsdf_map_file:fmFuzzTsdfMapFile
    rig_info_lines:fmFuzzRigInfoLines)
  set(FM_FUZZ_SOURCES "")
  foreach(fm_fuzz_pair ${FM_FUZZ_TARGETS})
    string(REPLACE ":" ";" fm_fuzz_parts ${fm_fuzz_pair})
    list(GET fm_fuzz_parts 0 fm_fuzz_target)
    list(GET fm_fuzz_parts 1 fm_fuzz_entry)
    set(fm_fuzz_file ${PROJECT_SOURCE_DIR}/test/fuzz/fuzz_${fm_fuzz_target}.cpp)
    set_source_files_properties(${fm_fuzz_file} PROPERTIES
      COMPILE_DEFINITIONS "FM_FUZZ_ENTRY=${fm_fuzz_entry};FM_FUZZ_IN_GTEST")
    list(APPEND FM_FUZZ_SOURCES ${fm_fuzz_file})
  endforeach()
  catkin_add_gtest(test_fuzz_regressions test/test_fuzz_regressions.cpp ${FM_FUZZ_SOURCES})
  target_link_libraries(test_fuzz_regressions fisheye_mapping_core GTest::gtest_main)
  target_include_directories(test_fuzz_regressions PRIVATE ${PROJECT_SOURCE_DIR}/src/tools)
  target_compile_definitions(test_fuzz_regressions PRIVATE FM_FUZZ_DIR="${PROJECT_SOURCE_DIR}/test/fuzz")
endif()
