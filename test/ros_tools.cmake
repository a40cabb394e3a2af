# Issue 30 part 5: the ROS tools and vehicle.launch as a ROS user meets them
# (included at the end of test/tests.cmake).
# rostopic echo -n1 / rostopic hz on every output topic of vehicle.launch.
fm_add_test(test_rostopic_echo_node ROSTEST test/launch/rostopic_echo.test
  SOURCES test/test_rostopic_echo_node.cpp DEPENDS fisheye_mapping_nodelets make_drive paced_player)
