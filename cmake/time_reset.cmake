# Time going backwards and stage faults: the rostests of the time reset
# (a drive played twice through sync, depth and masking) and of a depth
# manager killed and respawned mid-drive. Included at the end of CMakeLists.txt.
if(CATKIN_ENABLE_TESTING)
  add_rostest_gtest(test_time_reset_node test/launch/time_reset.test test/test_time_reset_node.cpp)
  target_link_libraries(test_time_reset_node ${catkin_LIBRARIES})
  add_dependencies(test_time_reset_node fisheye_mapping_nodelets make_drive paced_player
    ${PROJECT_NAME}_generate_messages_cpp)
  target_compile_definitions(test_time_reset_node PRIVATE FM_MAKE_DRIVE="$<TARGET_FILE:make_drive>"
    FM_PACED_PLAYER="$<TARGET_FILE:paced_player>" FM_TEST_DATA_DIR="${PROJECT_SOURCE_DIR}/test/data")
  add_rostest(test/launch/depth_respawn.test DEPENDENCIES test_time_reset_node)
endif()
