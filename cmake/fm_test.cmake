# fm_add_test(<name> SOURCES <file>... [ROSTEST <launch file>]
#             [LIBS <lib>...] [DEPENDS <target>...] [DEFINES <NAME=value>...]
#             [INCLUDES <dir>...])
# Registers a gtest (catkin_add_gtest, linked with gtest_main) or, with
# ROSTEST, a rostest gtest (its own main) linked with the core, the simulation
# library and catkin. Every test gets the package's directories as macros:
# FM_TEST_DIR, FM_TEST_DATA_DIR, FM_CONFIG_DIR, FM_SCRIPTS_DIR and FM_SHARED_DIR
# (../shared beside the real checkout; tests prefer $FISHEYE_MAPPING_SHARED_DIR).
# DEPENDS targets are built first; for an executable target T, the macro
# FM_<T upper-case> holds its path (e.g. make_drive -> FM_MAKE_DRIVE).
get_filename_component(FM_REAL_SOURCE_DIR ${PROJECT_SOURCE_DIR} REALPATH)
get_filename_component(FM_SHARED_DIR ${FM_REAL_SOURCE_DIR}/../shared ABSOLUTE)

function(fm_add_test name)
  cmake_parse_arguments(A "" "ROSTEST" "SOURCES;LIBS;DEPENDS;DEFINES;INCLUDES" ${ARGN})
  if(A_ROSTEST)
    add_rostest_gtest(${name} ${A_ROSTEST} ${A_SOURCES})
    target_link_libraries(${name} fisheye_mapping_sim ${catkin_LIBRARIES} ${A_LIBS})
  else()
    catkin_add_gtest(${name} ${A_SOURCES})
    target_link_libraries(${name} fisheye_mapping_sim ${catkin_LIBRARIES} GTest::gtest_main ${A_LIBS})
  endif()
  add_dependencies(${name} ${PROJECT_NAME}_generate_messages_cpp)
  set(tool_defines "")
  foreach(dep ${A_DEPENDS})
    add_dependencies(${name} ${dep})
    get_target_property(dep_type ${dep} TYPE)
    if(dep_type STREQUAL "EXECUTABLE")
      string(TOUPPER ${dep} dep_upper)
      list(APPEND tool_defines FM_${dep_upper}="$<TARGET_FILE:${dep}>")
    endif()
  endforeach()
  target_include_directories(${name} PRIVATE ${PROJECT_SOURCE_DIR}/test ${A_INCLUDES})
  target_compile_definitions(${name} PRIVATE
    FM_TEST_DIR="${PROJECT_SOURCE_DIR}/test" FM_TEST_DATA_DIR="${PROJECT_SOURCE_DIR}/test/data"
    FM_CONFIG_DIR="${PROJECT_SOURCE_DIR}/config" FM_SCRIPTS_DIR="${PROJECT_SOURCE_DIR}/scripts"
    FM_SHARED_DIR="${FM_SHARED_DIR}" ${tool_defines} ${A_DEFINES})
endfunction()
