# Seed benchmark models: triangle counts, closed oriented 2-manifolds, volumes, detail.
add_executable(seed_models_test seed_models_test.cc)
target_link_libraries(seed_models_test PRIVATE GTest::gtest_main haptic_core)
gtest_discover_tests(seed_models_test DISCOVERY_TIMEOUT 60)
