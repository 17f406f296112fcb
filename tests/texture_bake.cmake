# Haptic texture bake (DESIGN.md §2).
add_executable(texture_bake_test texture_bake_test.cc)
target_link_libraries(texture_bake_test PRIVATE GTest::gtest_main haptic_model_build)
gtest_discover_tests(texture_bake_test DISCOVERY_TIMEOUT 60)
