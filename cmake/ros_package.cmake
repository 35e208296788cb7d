# catkin, messages, dynamic_reconfigure and catkin_package(). Included before any target is declared.
set(MCFLOW_CATKIN_COMPONENTS
  roscpp nodelet pluginlib message_filters image_transport cv_bridge sensor_msgs geometry_msgs std_msgs
  visualization_msgs nav_msgs tf2 tf2_ros tf2_eigen tf2_msgs dynamic_reconfigure diagnostic_updater diagnostic_msgs
  message_generation rosbag rosgraph_msgs)
find_package(catkin REQUIRED COMPONENTS ${MCFLOW_CATKIN_COMPONENTS})

add_message_files(DIRECTORY msg FILES MotionSegment.msg SegmentArray.msg)
generate_messages(DEPENDENCIES std_msgs geometry_msgs)

# The .cfg reads names, types, defaults, ranges, units and descriptions from the core's parameter table
# (include/mc_flow/core/config_fields.def, which also generates mc_flow::Config).
generate_dynamic_reconfigure_options(cfg/McFlow.cfg)
# Regenerate the parameters whenever the core Config changes.
add_custom_command(OUTPUT ${CATKIN_DEVEL_PREFIX}/${CATKIN_PACKAGE_INCLUDE_DESTINATION}/McFlowConfig.h APPEND
  DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/include/mc_flow/core/config_fields.def)

# Exported to packages that find mc_flow through catkin: the nodelet library and the ROS-free libraries under it
# (solver, evaluation, file formats, file I/O, command line), in link order. The ROS-free ones are static archives; their own
# dependencies (Eigen, OpenMP, yaml-cpp, the CUDA runtime) come from cmake/mc_flow-extras.cmake.in.
# test/install/check_install.sh builds a package on them from the install space.
catkin_package(
  INCLUDE_DIRS include
  LIBRARIES mc_flow_nodelet mc_flow_io mc_flow_eval mc_flow_formats mc_flow_cli mc_flow_core
  CFG_EXTRAS mc_flow-extras.cmake  # from cmake/mc_flow-extras.cmake.in
  CATKIN_DEPENDS roscpp nodelet message_filters image_transport cv_bridge sensor_msgs geometry_msgs std_msgs
    visualization_msgs nav_msgs tf2_ros dynamic_reconfigure diagnostic_updater message_runtime)
