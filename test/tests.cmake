# The package's tests, one fm_add_test per test (cmake/fm_test.cmake).
# Included by CMakeLists.txt when CATKIN_ENABLE_TESTING is on.
find_package(rostest REQUIRED)
include(${PROJECT_SOURCE_DIR}/cmake/fm_test.cmake)

# --- camera and rig --------------------------------------------------------
fm_add_test(test_camera_model SOURCES test/test_camera_model.cpp)
fm_add_test(test_camera_model_opencl SOURCES test/test_camera_model_opencl.cpp)
fm_add_test(test_rig_calibration SOURCES test/test_rig_calibration.cpp)
fm_add_test(test_rig_info SOURCES test/test_rig_info.cpp DEPENDS rig_info)
fm_add_test(test_rig_refinement SOURCES test/test_rig_refinement.cpp DEPENDS refine_rig make_drive)
fm_add_test(test_online_calibration SOURCES test/test_online_calibration.cpp)
fm_add_test(test_rig_tf_publisher ROSTEST test/launch/rig_tf_publisher.test
  SOURCES test/test_rig_tf_publisher.cpp DEPENDS fisheye_mapping_nodelets)

# --- frame sets and playback -----------------------------------------------
fm_add_test(test_frame_sync SOURCES test/test_frame_sync.cpp)
fm_add_test(test_frame_pacer SOURCES test/test_frame_pacer.cpp)
fm_add_test(test_sync_node ROSTEST test/launch/sync.test
  SOURCES test/test_sync_node.cpp DEPENDS fisheye_mapping_nodelets)
fm_add_test(test_paced_player_node ROSTEST test/launch/paced_player.test
  SOURCES test/test_paced_player_node.cpp DEPENDS paced_player)
fm_add_test(test_synthetic_drive SOURCES test/test_synthetic_drive.cpp DEPENDS make_drive)

# --- plane-sweep depth -----------------------------------------------------
fm_add_test(test_plane_sweep SOURCES test/test_plane_sweep.cpp)
fm_add_test(test_plane_sweep_tool SOURCES test/test_plane_sweep_tool.cpp DEPENDS plane_sweep_depth)
fm_add_test(test_depth_consistency SOURCES test/test_depth_consistency.cpp DEPENDS depth_eval)
fm_add_test(test_depth_node ROSTEST test/launch/depth.test
  SOURCES test/test_depth_node.cpp DEPENDS fisheye_mapping_nodelets)

# --- detection and masking -------------------------------------------------
fm_add_test(test_detector SOURCES test/test_detector.cpp)
fm_add_test(test_depth_mask SOURCES test/test_depth_mask.cpp)
fm_add_test(test_vehicle_motion SOURCES test/test_vehicle_motion.cpp)
fm_add_test(test_dynamic_objects_node ROSTEST test/launch/dynamic_objects.test
  SOURCES test/test_dynamic_objects_node.cpp DEPENDS fisheye_mapping_nodelets)

# --- TSDF fusion and maps --------------------------------------------------
fm_add_test(test_tsdf SOURCES test/test_tsdf.cpp)
fm_add_test(test_occupancy_grid SOURCES test/test_occupancy_grid.cpp)
fm_add_test(test_tsdf_map_file SOURCES test/test_tsdf_map_file.cpp DEPENDS map_tool)
fm_add_test(test_map_session SOURCES test/test_map_session.cpp)
fm_add_test(test_tsdf_fusion_stage SOURCES test/test_tsdf_fusion_stage.cpp)
fm_add_test(test_map_accuracy SOURCES test/test_map_accuracy.cpp DEPENDS map_accuracy)
fm_add_test(test_tsdf_node ROSTEST test/launch/tsdf.test
  SOURCES test/test_tsdf_node.cpp DEPENDS fisheye_mapping_nodelets)
# Depth and Tsdf loaded in the test's process with a fault hook that throws in their callbacks.
fm_add_test(test_fault_injection_node ROSTEST test/launch/fault_injection.test
  SOURCES test/test_fault_injection_node.cpp LIBS fisheye_mapping_ros DEPENDS fisheye_mapping_nodelets)
# The fusion node's life cycle: SIGTERM saves, a respawn keeps the saved map,
# lost swap files do not abort. The test starts and signals the nodes itself.
fm_add_test(test_tsdf_lifecycle_node ROSTEST test/launch/tsdf_lifecycle.test
  SOURCES test/test_tsdf_lifecycle_node.cpp DEPENDS fisheye_mapping_nodelets)

# --- the whole pipeline ----------------------------------------------------
fm_add_test(test_offline_mapper SOURCES test/test_offline_mapper.cpp DEPENDS offline_mapper make_drive plane_sweep_depth)
fm_add_test(test_multihost SOURCES test/test_multihost.cpp DEPENDS fisheye_mapping_nodelets make_drive)
fm_add_test(test_vehicle_e2e_node ROSTEST test/launch/vehicle_e2e.test
  SOURCES test/test_vehicle_e2e_node.cpp DEPENDS fisheye_mapping_nodelets make_drive paced_player offline_mapper)
# Time going backwards and stage faults: a drive played twice through sync,
# depth and masking; a depth manager killed and respawned mid-drive.
fm_add_test(test_time_reset_node ROSTEST test/launch/time_reset.test
  SOURCES test/test_time_reset_node.cpp DEPENDS fisheye_mapping_nodelets make_drive paced_player)
add_rostest(test/launch/depth_respawn.test DEPENDENCIES test_time_reset_node)

# --- command-line tools ----------------------------------------------------
# Option parsing (src/tools/cli.h), rejected inputs, and the regression inputs
# of the fuzz targets (test/fuzz/<target>/, built with clang by scripts/checks/fuzz)
# replayed through the same entry points with the normal build.
fm_add_test(test_tool_options SOURCES test/test_tool_options.cpp INCLUDES ${PROJECT_SOURCE_DIR}/src/tools
  DEPENDS tsdf_benchmark depth_benchmark detector_benchmark detect_image)
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
fm_add_test(test_fuzz_regressions SOURCES test/test_fuzz_regressions.cpp ${FM_FUZZ_SOURCES}
  INCLUDES ${PROJECT_SOURCE_DIR}/src/tools DEFINES FM_FUZZ_DIR="${PROJECT_SOURCE_DIR}/test/fuzz")
fm_add_test(test_param_declarations SOURCES test/test_param_declarations.cpp LIBS fisheye_mapping_ros DEPENDS fisheye_mapping_gencfg
  DEFINES FM_DOCS_DIR="${PROJECT_SOURCE_DIR}/docs")
fm_add_test(test_rig_geometry SOURCES test/test_rig_geometry.cpp)
fm_add_test(test_frame_set_mapper SOURCES test/test_frame_set_mapper.cpp)
fm_add_test(test_conversions SOURCES test/test_conversions.cpp LIBS fisheye_mapping_ros)
fm_add_test(test_mesh_distance SOURCES test/test_mesh_distance.cpp)
fm_add_test(test_paths SOURCES test/test_paths.cpp)
fm_add_test(test_safe_open SOURCES test/test_safe_open.cpp)
fm_add_test(test_safe_write SOURCES test/test_safe_write.cpp)
fm_add_test(test_mesh_export SOURCES test/test_mesh_export.cpp)
fm_add_test(test_mesh_markers SOURCES test/test_mesh_markers.cpp LIBS fisheye_mapping_ros)
fm_add_test(test_camera_info SOURCES test/test_camera_info.cpp LIBS fisheye_mapping_ros)
fm_add_test(test_zdepth SOURCES test/test_zdepth.cpp)
fm_add_test(test_stage_stats SOURCES test/test_stage_stats.cpp)
fm_add_test(test_stage_monitor SOURCES test/test_stage_monitor.cpp LIBS fisheye_mapping_ros)
add_dependencies(test_tool_options param_docs rig_info refine_rig make_drive depth_eval map_accuracy map_tool offline_mapper paced_player plane_sweep_depth)
fm_add_test(test_own_rig_node ROSTEST test/launch/own_rig.test SOURCES test/test_own_rig_node.cpp DEPENDS fisheye_mapping_nodelets make_drive paced_player)
fm_add_test(test_detector_eval SOURCES test/test_detector_eval.cpp DEPENDS detector_eval)
fm_add_test(test_launch_files SOURCES test/test_launch_files.cpp INCLUDES ${PROJECT_SOURCE_DIR}/test)
include(${CMAKE_CURRENT_LIST_DIR}/ros_tools.cmake)
# Issue 29: the nodelets' ROS-free bookkeeping and their shared glue.
fm_add_test(test_latest_worker SOURCES test/test_latest_worker.cpp)
fm_add_test(test_sync_report SOURCES test/test_sync_report.cpp)
fm_add_test(test_mask_decisions SOURCES test/test_mask_decisions.cpp)
fm_add_test(test_nodelet_glue SOURCES test/test_nodelet_glue.cpp LIBS fisheye_mapping_ros)
# The detector registry and the detector_model tool the launch files run.
fm_add_test(test_detector_registry SOURCES test/test_detector_registry.cpp)
add_dependencies(test_launch_files detector_model)
add_dependencies(test_dynamic_objects_node detector_model)
add_dependencies(test_tool_options detector_model)
add_dependencies(test_rostopic_echo_node detector_model)
