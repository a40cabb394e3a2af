# Map integrity: validated, checksummed TSDF map files (core tsdf_io.cpp), the
# map_tool (info / check / convert) and their tests. Included at the end of
# CMakeLists.txt.
target_sources(fisheye_mapping_core PRIVATE ${PROJECT_SOURCE_DIR}/src/core/tsdf_io.cpp)

add_executable(map_tool src/tools/map_tool.cpp)
target_link_libraries(map_tool fisheye_mapping_core)
install(TARGETS map_tool RUNTIME DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})

if(CATKIN_ENABLE_TESTING)
  catkin_add_gtest(test_tsdf_map_file test/test_tsdf_map_file.cpp)
  target_link_libraries(test_tsdf_map_file fisheye_mapping_core GTest::gtest_main)
  add_dependencies(test_tsdf_map_file map_tool)
  target_compile_definitions(test_tsdf_map_file PRIVATE FM_MAP_TOOL="$<TARGET_FILE:map_tool>")

  # The fusion node's life cycle: SIGTERM saves, a respawn keeps the saved map,
  # lost swap files do not abort. The test starts and signals the nodes itself.
  add_rostest_gtest(test_tsdf_lifecycle_node test/launch/tsdf_lifecycle.test test/test_tsdf_lifecycle_node.cpp)
  target_link_libraries(test_tsdf_lifecycle_node fisheye_mapping_core ${catkin_LIBRARIES})
  add_dependencies(test_tsdf_lifecycle_node fisheye_mapping_nodelets ${PROJECT_NAME}_generate_messages_cpp)
endif()
