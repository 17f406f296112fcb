# Force Dimension and OpenHaptics backends against fake vendor libraries built here (shared
# libraries with the vendors' C symbols that play a scripted handle and record what they are
# sent), loaded by path through the backends' own dlopen. Each test is its own program: it counts
# allocations (allocation_counter.h, hence ENABLE_EXPORTS).
foreach(fake fake_dhd fake_hd)
  add_library(${fake} SHARED ${fake}.cc)
  add_library(${fake}_incomplete SHARED ${fake}.cc)
endforeach()
target_compile_definitions(fake_dhd_incomplete PRIVATE FAKE_DHD_INCOMPLETE)
target_compile_definitions(fake_hd_incomplete PRIVATE FAKE_HD_INCOMPLETE)

foreach(pair "force_dimension_test;fake_dhd;HT_FAKE_DHD" "openhaptics_test;fake_hd;HT_FAKE_HD")
  list(GET pair 0 test)
  list(GET pair 1 fake)
  list(GET pair 2 define)
  add_executable(${test} ${test}.cc)
  target_include_directories(${test} PRIVATE ${CMAKE_CURRENT_SOURCE_DIR})
  target_link_libraries(${test} PRIVATE GTest::gtest_main master_station_lib)
  target_compile_definitions(${test} PRIVATE ${define}="$<TARGET_FILE:${fake}>"
                             ${define}_INCOMPLETE="$<TARGET_FILE:${fake}_incomplete>")
  add_dependencies(${test} ${fake} ${fake}_incomplete)
  set_target_properties(${test} PROPERTIES ENABLE_EXPORTS ON)  # allocation_counter.h
  gtest_discover_tests(${test} DISCOVERY_TIMEOUT 60)
endforeach()
