# libFuzzer targets for every loader a user's file reaches (-DMCFLOW_FUZZ=ON, clang; docs/TESTING.md).
# The libraries are built with -fsanitize=fuzzer-no-link,address,undefined (CMakeLists.txt); each target
# links libFuzzer's main. ctest runs each for 2000 inputs or 20 s, whichever ends first (depth images
# decode at only 4-30 inputs/s under the sanitizers, against thousands for the other loaders), on seeds from
# `mcflow synth`.
add_executable(fuzz_make_seeds ${CMAKE_CURRENT_SOURCE_DIR}/test/fuzz/make_seeds.cpp)
target_link_libraries(fuzz_make_seeds PRIVATE mc_flow_io)
set(MCFLOW_FUZZ_TARGETS colour_image depth_image depth_pfm flo camera_info config_file)
foreach(target ${MCFLOW_FUZZ_TARGETS})
  add_executable(fuzz_${target} ${CMAKE_CURRENT_SOURCE_DIR}/test/fuzz/fuzz_${target}.cpp)
  target_link_libraries(fuzz_${target} PRIVATE mc_flow_io)
  target_link_options(fuzz_${target} PRIVATE -fsanitize=fuzzer)
  set_target_properties(fuzz_${target} PROPERTIES RUNTIME_OUTPUT_DIRECTORY $<TARGET_FILE_DIR:mcflow>)
  add_test(NAME fuzz.${target} COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/test/fuzz/run_fuzz.sh
           $<TARGET_FILE_DIR:mcflow> ${target} -runs=2000 -max_total_time=20)
  set_tests_properties(fuzz.${target} PROPERTIES LABELS fuzz)
endforeach()
set_target_properties(fuzz_make_seeds PROPERTIES RUNTIME_OUTPUT_DIRECTORY $<TARGET_FILE_DIR:mcflow>)
