# libFuzzer targets for every loader a user's file reaches (-DMCFLOW_FUZZ=ON, clang; docs/TESTING.md).
# The libraries are built with -fsanitize=fuzzer-no-link,address,undefined (CMakeLists.txt); each target
# links libFuzzer's main. ctest's smoke run (label fuzz; CI runs it from scripts/test_sanitized.sh core-io) gives each
# target a fixed count of inputs from the seeds that `mcflow synth` renders, with a fixed -seed: the same inputs on
# every machine, so a pass or a finding never depends on the machine's speed. No -max_total_time; ctest's TIMEOUT is
# the safety cap, and running into it fails the test. depth_image gets fewer inputs: its images decode at only
# 4-30 inputs/s under the sanitizers, against thousands for the other loaders.
add_executable(fuzz_make_seeds ${CMAKE_CURRENT_SOURCE_DIR}/test/fuzz/make_seeds.cpp)
target_link_libraries(fuzz_make_seeds PRIVATE mc_flow_io)
set(MCFLOW_FUZZ_TARGETS colour_image depth_image depth_pfm flo camera_info config_file)
add_custom_target(fuzz_targets DEPENDS fuzz_make_seeds)
set(MCFLOW_FUZZ_RUNS 2000)
set(MCFLOW_FUZZ_RUNS_depth_image 300)
foreach(target ${MCFLOW_FUZZ_TARGETS})
  add_executable(fuzz_${target} ${CMAKE_CURRENT_SOURCE_DIR}/test/fuzz/fuzz_${target}.cpp)
  target_link_libraries(fuzz_${target} PRIVATE mc_flow_io)
  target_link_options(fuzz_${target} PRIVATE -fsanitize=fuzzer)
  add_dependencies(fuzz_targets fuzz_${target})
  set_target_properties(fuzz_${target} PROPERTIES RUNTIME_OUTPUT_DIRECTORY $<TARGET_FILE_DIR:mcflow>)
  if(DEFINED MCFLOW_FUZZ_RUNS_${target})
    set(runs ${MCFLOW_FUZZ_RUNS_${target}})
  else()
    set(runs ${MCFLOW_FUZZ_RUNS})
  endif()
  add_test(NAME fuzz.${target} COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/test/fuzz/run_fuzz.sh
           $<TARGET_FILE_DIR:mcflow> ${target} -runs=${runs} -seed=1)
  set_tests_properties(fuzz.${target} PROPERTIES LABELS fuzz TIMEOUT 300)
endforeach()
set_target_properties(fuzz_make_seeds PROPERTIES RUNTIME_OUTPUT_DIRECTORY $<TARGET_FILE_DIR:mcflow>)
