# Depth checks without ground truth (frame-to-frame consistency, road
# flatness): core source and its tests. Included at the end of CMakeLists.txt.
target_sources(fisheye_mapping_core PRIVATE ${PROJECT_SOURCE_DIR}/src/core/depth_consistency.cpp)

if(CATKIN_ENABLE_TESTING)
  catkin_add_gtest(test_depth_consistency test/test_depth_consistency.cpp)
  target_link_libraries(test_depth_consistency fisheye_mapping_core GTest::gtest_main)
  # The real-data test runs depth_eval vcharge on ../shared (skipped without it).
  add_dependencies(test_depth_consistency depth_eval)
  target_compile_definitions(test_depth_consistency PRIVATE FM_SHARED_DIR="${FM_SHARED_DIR}"
    FM_DEPTH_EVAL="$<TARGET_FILE:depth_eval>")
endif()
