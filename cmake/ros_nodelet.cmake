# The nodelet library, its tools and its tests (gtest + rostest). Included after the core targets.

# What the ROS code includes: the package's headers, ROS's and OpenCV's.
set(MCFLOW_ROS_INCLUDE_DIRS ${CMAKE_CURRENT_SOURCE_DIR}/include ${catkin_INCLUDE_DIRS} ${OpenCV_INCLUDE_DIRS})

add_library(mc_flow_nodelet SHARED
  src/ros/conversions.cpp
  src/ros/input_gate.cpp
  src/ros/input_subscription.cpp
  src/ros/input_watch.cpp
  src/ros/message_validation.cpp
  src/ros/node_parameters.cpp
  src/ros/node_status.cpp
  src/ros/output_publishers.cpp
  src/ros/reconfigure.cpp
  src/ros/startup_report.cpp
  src/ros/mc_flow_nodelet.cpp)
target_include_directories(mc_flow_nodelet PUBLIC ${MCFLOW_ROS_INCLUDE_DIRS})
target_link_libraries(mc_flow_nodelet PUBLIC mc_flow_core ${catkin_LIBRARIES} ${OpenCV_LIBS})
target_compile_options(mc_flow_nodelet PRIVATE -Wall -Wextra)
add_dependencies(mc_flow_nodelet ${PROJECT_NAME}_generate_messages_cpp ${PROJECT_NAME}_gencfg)
set_target_properties(mc_flow_nodelet PROPERTIES
  LIBRARY_OUTPUT_DIRECTORY ${CATKIN_DEVEL_PREFIX}/${CATKIN_PACKAGE_LIB_DESTINATION})

# Rosbags for `mcflow run-seq --bag`: the nodelet's message conversions over a bag's topics. The tool is declared
# without ROS (CMakeLists.txt); here it gains the bag reader.
add_library(mc_flow_bag STATIC src/ros/bag_sequence.cpp)
target_link_libraries(mc_flow_bag PUBLIC mc_flow_nodelet)
target_compile_options(mc_flow_bag PRIVATE -Wall -Wextra)
if(TARGET mcflow)
  target_link_libraries(mcflow PRIVATE mc_flow_bag)
  target_compile_definitions(mcflow PRIVATE MCFLOW_WITH_ROSBAG=1)
endif()

# Writes the demo bag: a synthetic RGB-D sequence with moving parts (no camera needed).
add_executable(make_synthetic_bag src/ros/make_synthetic_bag.cpp)
target_link_libraries(make_synthetic_bag PRIVATE mc_flow_nodelet mc_flow_eval mc_flow_cli)
set_target_properties(make_synthetic_bag PROPERTIES
  RUNTIME_OUTPUT_DIRECTORY ${CATKIN_DEVEL_PREFIX}/${CATKIN_PACKAGE_BIN_DESTINATION})

# Issue 6: the nodelet's own work per pair (conversions, output messages, serialisation) without a master.
# A benchmark, not a test: docs/PERFORMANCE.md, "Nodelet overhead per pair".
add_executable(mcflow_bench_nodelet src/ros/mcflow_bench_nodelet.cpp)
target_link_libraries(mcflow_bench_nodelet PRIVATE mc_flow_nodelet mc_flow_io mc_flow_testing)
target_compile_options(mcflow_bench_nodelet PRIVATE -Wall -Wextra)

# The install space (catkin_make install, catkin_make_isolated --install; test/install/check_install.sh): the nodelet
# and the libraries catkin_package() exports in lib/, the tools in lib/mc_flow (rosrun mc_flow mcflow), every header
# but the benchmark and test harness's (include/mc_flow/testing) under include/mc_flow/.
install(TARGETS mc_flow_nodelet mc_flow_io mc_flow_eval mc_flow_formats mc_flow_cli mc_flow_core
  ARCHIVE DESTINATION ${CATKIN_PACKAGE_LIB_DESTINATION}
  LIBRARY DESTINATION ${CATKIN_PACKAGE_LIB_DESTINATION})
install(TARGETS mcflow make_synthetic_bag RUNTIME DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})
install(DIRECTORY include/mc_flow/ DESTINATION ${CATKIN_PACKAGE_INCLUDE_DESTINATION}
  PATTERN testing EXCLUDE)
install(FILES nodelet_plugins.xml DESTINATION ${CATKIN_PACKAGE_SHARE_DESTINATION})
install(DIRECTORY launch rviz DESTINATION ${CATKIN_PACKAGE_SHARE_DESTINATION})
catkin_install_python(PROGRAMS scripts/demo_monitor.py scripts/start_rviz.py DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})

if(MCFLOW_BUILD_TESTS AND CATKIN_ENABLE_TESTING)
  find_package(GTest REQUIRED)
  include(GoogleTest)
  if(NOT TARGET tests)
    add_custom_target(tests)
  endif()

  # Unit tests that need no running node: conversions, message validation, reconfigure mapping, the nodelet's parts.
  add_executable(test_ros_units
    test/ros/test_conversions.cpp
    test/ros/test_message_validation.cpp
    test/ros/test_reconfigure.cpp
    test/ros/test_input_watch.cpp
    test/ros/test_input_gate.cpp
    test/ros/test_input_subscription.cpp
    test/ros/test_node_status.cpp
    test/ros/test_node_parameters.cpp
    test/ros/test_startup_report.cpp)
  target_link_libraries(test_ros_units PRIVATE mc_flow_nodelet GTest::gtest GTest::gtest_main)
  target_compile_definitions(test_ros_units PRIVATE MCFLOW_LAUNCH_DIR="${CMAKE_CURRENT_SOURCE_DIR}/launch")
  gtest_discover_tests(test_ros_units DISCOVERY_MODE PRE_TEST TEST_PREFIX "ros." PROPERTIES LABELS test_ros_units)
  if(MCFLOW_SANITIZE)
    mcflow_sanitizer_environment(test_ros_units)
  endif()
  add_dependencies(tests test_ros_units)

  # Rosbags as sequences: the reader on bags written by the test, and `mcflow run-seq --bag` end to end.
  add_executable(test_ros_bag test/ros/test_bag_sequence.cpp)
  target_link_libraries(test_ros_bag PRIVATE mc_flow_bag mc_flow_testing GTest::gtest GTest::gtest_main)
  target_include_directories(test_ros_bag PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/test)
  target_compile_definitions(test_ros_bag PRIVATE MCFLOW_CLI_PATH="$<TARGET_FILE:mcflow>")
  add_dependencies(test_ros_bag mcflow)
  gtest_discover_tests(test_ros_bag DISCOVERY_MODE PRE_TEST TEST_PREFIX "ros." PROPERTIES LABELS test_ros_bag)
  if(MCFLOW_SANITIZE)
    mcflow_sanitizer_environment(test_ros_bag)
  endif()
  add_dependencies(tests test_ros_bag)

  # The message validation and the input conversions again, built with ASan+UBSan: a header that slips
  # past the validation is caught reading out of bounds even where it would not crash. The core library
  # it links is not instrumented (mixing is supported); the code under test is.
  add_executable(test_message_validation_sanitized
    test/ros/test_message_validation.cpp
    src/ros/message_validation.cpp
    src/ros/conversions.cpp
    src/core/buffer_layout.cpp)
  target_include_directories(test_message_validation_sanitized PRIVATE ${MCFLOW_ROS_INCLUDE_DIRS})
  target_compile_options(test_message_validation_sanitized PRIVATE
    -fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer -g -O1)
  target_link_options(test_message_validation_sanitized PRIVATE -fsanitize=address,undefined)
  target_link_libraries(test_message_validation_sanitized PRIVATE
    mc_flow_core ${catkin_LIBRARIES} ${OpenCV_LIBS} GTest::gtest GTest::gtest_main)
  add_dependencies(test_message_validation_sanitized ${PROJECT_NAME}_generate_messages_cpp)
  add_test(NAME ros.MessageValidationUnderAsanUbsan COMMAND test_message_validation_sanitized)
  set_tests_properties(ros.MessageValidationUnderAsanUbsan PROPERTIES
    ENVIRONMENT "ASAN_OPTIONS=detect_leaks=1:abort_on_error=1;UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1")
  add_dependencies(tests test_message_validation_sanitized)

  # The nodelet in a process of its own with an injected backend fault (backend_fault.test, lazy_and_drops.test): the
  # fault hook lives in the test library, not in the product.
  add_executable(nodelet_with_fault test/ros/nodelet_with_fault.cpp)
  target_link_libraries(nodelet_with_fault PRIVATE mc_flow_nodelet mc_flow_testing)
  set_target_properties(nodelet_with_fault PROPERTIES
    RUNTIME_OUTPUT_DIRECTORY ${CATKIN_DEVEL_PREFIX}/${CATKIN_PACKAGE_BIN_DESTINATION})
  add_dependencies(tests nodelet_with_fault)

  # Node-level tests: rostest starts its own master on a free port, so ctest -j is safe.
  find_package(rostest REQUIRED)
  set(MCFLOW_ROSTEST_NODES synthetic bad_input lazy_and_drops storm backend_fault stream prior_frame)
  foreach(name ${MCFLOW_ROSTEST_NODES})
    add_rostest_gtest(rostest_${name} test/ros/${name}.test test/ros/rostest_${name}.cpp test/ros/rostest_common.cpp)
    target_include_directories(rostest_${name} PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/test/ros)
    target_link_libraries(rostest_${name} mc_flow_nodelet mc_flow_testing ${GTEST_LIBRARIES})
    add_dependencies(rostest_${name} mc_flow_nodelet)
    add_dependencies(tests rostest_${name})
  endforeach()

  # Scripted checks of what a user meets: the tools the README names start; demo.launch with a bag of
  # only the three camera topics (relative path, output frames vs the rviz Fixed Frame, bad paths).
  add_test(NAME ros.ToolsTheReadmeUses
    COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/test/ros/check_tools.sh ${CMAKE_CURRENT_SOURCE_DIR}/README.md ${CATKIN_DEVEL_PREFIX})
  add_test(NAME ros.DemoLaunchWithARecordedBag
    COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/test/ros/check_bag_launch.sh ${CMAKE_CURRENT_SOURCE_DIR} ${CATKIN_DEVEL_PREFIX})
  set_tests_properties(ros.DemoLaunchWithARecordedBag PROPERTIES TIMEOUT 400 RUN_SERIAL TRUE)
  # A standalone nodelet asked for a transport whose plug-in is missing: named, raw instead, clean exit.
  add_test(NAME ros.MissingTransportFallsBackToRaw
    COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/test/ros/check_transport_fallback.sh ${CATKIN_DEVEL_PREFIX})
  set_tests_properties(ros.MissingTransportFallsBackToRaw PROPERTIES TIMEOUT 180)
  # The install space as a ROS user meets it: the built package installed into a temporary prefix, a downstream catkin
  # package built and run against it, `mcflow demo` and demo.launch from it. Not in a sanitized build (a downstream
  # package cannot link instrumented archives without the sanitizer runtimes).
  if(NOT MCFLOW_SANITIZE)
    add_test(NAME install.BuildOnTheInstallSpace
      COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/test/install/check_install.sh ${CMAKE_CURRENT_SOURCE_DIR} ${CMAKE_BINARY_DIR})
    set_tests_properties(install.BuildOnTheInstallSpace PROPERTIES TIMEOUT 600)
  endif()
  # rviz's view follows the Fixed Frame: optical (auto) along +z, a body frame (camera_link) along +x.
  add_test(NAME ros.RvizViewFollowsTheFixedFrame
    COMMAND /usr/bin/python3 ${CMAKE_CURRENT_SOURCE_DIR}/test/ros/check_rviz_view.py ${CMAKE_CURRENT_SOURCE_DIR})
endif()
