# Contact clustering: synthetic pair sets (separated spots, corners, chains, capacity, faults).
add_executable(contact_clustering_test contact_clustering_test.cc)
target_link_libraries(contact_clustering_test PRIVATE GTest::gtest_main haptic_core)
gtest_discover_tests(contact_clustering_test DISCOVERY_TIMEOUT 60)
