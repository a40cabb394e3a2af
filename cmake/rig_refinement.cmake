# Rig refinement: extrinsic rotation correction from image features (core
# source, refine_rig tool, test). Included at the end of CMakeLists.txt.

# ORB / matching (features2d) and KLT (video). The imported targets exist once
# OpenCV's config has run; OpenCV_LIBS is kept as the main find_package set it.
set(FM_RIG_REFINEMENT_SAVED_OPENCV_LIBS "${OpenCV_LIBS}")
if(NOT TARGET opencv_features2d OR NOT TARGET opencv_video)
  find_package(OpenCV REQUIRED COMPONENTS features2d video)
endif()
set(OpenCV_LIBS "${FM_RIG_REFINEMENT_SAVED_OPENCV_LIBS}")

target_sources(fisheye_mapping_core PRIVATE src/core/rig_refinement.cpp)
target_link_libraries(fisheye_mapping_core PUBLIC opencv_features2d opencv_video)

add_executable(refine_rig src/tools/refine_rig.cpp)
target_link_libraries(refine_rig fisheye_mapping_core ${catkin_LIBRARIES})
install(TARGETS refine_rig RUNTIME DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})

if(CATKIN_ENABLE_TESTING)
  catkin_add_gtest(test_rig_refinement test/test_rig_refinement.cpp)
  target_link_libraries(test_rig_refinement fisheye_mapping_core ${catkin_LIBRARIES} GTest::gtest_main)
  add_dependencies(test_rig_refinement refine_rig make_drive)
  target_compile_definitions(test_rig_refinement PRIVATE FM_CONFIG_DIR="${PROJECT_SOURCE_DIR}/config"
    FM_REFINE_RIG="$<TARGET_FILE:refine_rig>" FM_MAKE_DRIVE="$<TARGET_FILE:make_drive>")
endif()
