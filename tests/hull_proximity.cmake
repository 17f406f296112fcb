# Proximity query between convex-hull hierarchies, checked against FCL (mesh distance and
# collision on the same coarse triangles) and a brute-force libccd leaf-pair test.
if(NOT TARGET fcl)
  find_package(fcl 0.7 CONFIG REQUIRED)
endif()
add_executable(hull_proximity_test hull_proximity_test.cc)
target_link_libraries(hull_proximity_test PRIVATE GTest::gtest_main haptic_model_build fcl ccd)
gtest_discover_tests(hull_proximity_test DISCOVERY_TIMEOUT 60)
