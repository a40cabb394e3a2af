# Issue 30 part 5: the ROS tools and vehicle.launch as a ROS user meets them
# (included at the end of test/tests.cmake).
# rostopic echo -n1 / rostopic hz on every output topic of vehicle.launch.
fm_add_test(test_rostopic_echo_node ROSTEST test/launch/rostopic_echo.test
  SOURCES test/test_rostopic_echo_node.cpp DEPENDS fisheye_mapping_nodelets make_drive paced_player)
# vehicle.launch's paced player: a dead player ends the launch (required), the
# map saved on the way down; rig_source:=camera_info from the player's
# CameraInfo (publish_camera_info:=true); no TF_REPEATED_DATA while holding.
fm_add_test(test_player_launch_node ROSTEST test/launch/player_launch.test
  SOURCES test/test_player_launch_node.cpp DEPENDS fisheye_mapping_nodelets make_drive paced_player)
