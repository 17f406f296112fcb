# The impairment relay (included from tests/CMakeLists.txt): spec parsing, the seeded model's
# statistics, and ht_relay as a real process between two UDP sockets of the test.
add_executable(impairment_test ${CMAKE_CURRENT_SOURCE_DIR}/impairment_test.cc)
target_link_libraries(impairment_test PRIVATE GTest::gtest_main impairment)
target_compile_definitions(impairment_test PRIVATE HT_RELAY_EXE="$<TARGET_FILE:ht_relay>")
add_dependencies(impairment_test ht_relay)
gtest_discover_tests(impairment_test DISCOVERY_TIMEOUT 60)
