# Convex-hull hierarchy: the data structure (haptic_core) and its qhull builder
# (haptic_model_build).
add_executable(hull_hierarchy_test hull_hierarchy_test.cc)
target_link_libraries(hull_hierarchy_test PRIVATE GTest::gtest_main haptic_model_build)
gtest_discover_tests(hull_hierarchy_test DISCOVERY_TIMEOUT 60)
