# Unit and end-to-end tests (gtest via ctest), labelled with their executable (ctest -L test_io). The ROS
# tests (rostest) are added in ros_nodelet.cmake.
find_package(GTest REQUIRED)
include(GoogleTest)

# Real pairs live beside the repository (../shared/data); CI sets MCFLOW_SHARED_DATA itself.
if(DEFINED ENV{MCFLOW_SHARED_DATA})
  set(MCFLOW_SHARED_DATA_DEFAULT $ENV{MCFLOW_SHARED_DATA})
else()
  get_filename_component(MCFLOW_SHARED_DATA_DEFAULT ${CMAKE_CURRENT_SOURCE_DIR}/../shared/data ABSOLUTE)
endif()

function(mcflow_add_gtest name)
  file(GLOB sources CONFIGURE_DEPENDS ${ARGN})
  if(NOT sources)
    return()
  endif()
  add_executable(${name} ${sources})
  target_link_libraries(${name} PRIVATE ${MCFLOW_TEST_LIBS} GTest::gtest GTest::gtest_main)
  target_include_directories(${name} PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/test)
  gtest_discover_tests(${name} DISCOVERY_MODE PRE_TEST
    PROPERTIES ENVIRONMENT "MCFLOW_SHARED_DATA=${MCFLOW_SHARED_DATA_DEFAULT}" LABELS ${name})
  if(MCFLOW_SANITIZE)
    mcflow_sanitizer_environment(${name} "MCFLOW_SHARED_DATA=${MCFLOW_SHARED_DATA_DEFAULT}")
  endif()
  add_dependencies(tests ${name})
endfunction()

if(NOT TARGET tests)
  add_custom_target(tests)
endif()

set(MCFLOW_TEST_LIBS mc_flow_core mc_flow_testing)
mcflow_add_gtest(test_core ${CMAKE_CURRENT_SOURCE_DIR}/test/core/*.cpp)
# GPU tests skip (visibly, GTEST_SKIP with the reason) where no CUDA GPU is usable.
# Kernels of the tests themselves (a faulting kernel for the GPU-fault test) only where CUDA is compiled in.
set(MCFLOW_TEST_CUDA_SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test/cuda/*.cpp)
if(MCFLOW_HAVE_CUDA)
  list(APPEND MCFLOW_TEST_CUDA_SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test/cuda/*.cu)
endif()
mcflow_add_gtest(test_cuda ${MCFLOW_TEST_CUDA_SOURCES})
if(MCFLOW_WITH_OPENCV)
  set(MCFLOW_TEST_LIBS mc_flow_io)
  mcflow_add_gtest(test_io ${CMAKE_CURRENT_SOURCE_DIR}/test/io/*.cpp)
  target_compile_definitions(test_io PRIVATE MCFLOW_CLI_PATH="$<TARGET_FILE:mcflow>"
                                            MCFLOW_BENCH_PATH="$<TARGET_FILE:mcflow_bench>"
                                            MCFLOW_BENCH_STREAM_PATH="$<TARGET_FILE:mcflow_bench_stream>")
  add_dependencies(test_io mcflow mcflow_bench mcflow_bench_stream)
  if(TARGET mc_flow_bag)  # the tool reads rosbags (ros_nodelet.cmake)
    target_compile_definitions(test_io PRIVATE MCFLOW_CLI_HAS_BAG=1)
  endif()
endif()
# Every tracked C++ and CUDA file formatted as .clang-format says (not in the sanitized builds: one check is enough).
if(NOT MCFLOW_SANITIZE)
  add_test(NAME format.ClangFormat COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/scripts/check_format.sh)
endif()
