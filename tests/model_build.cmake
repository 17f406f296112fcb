# The haptic model build (decimation, pipeline, cache) and scene building.
add_executable(model_build_test model_build_test.cc)
target_link_libraries(model_build_test PRIVATE GTest::gtest_main haptic_model_build)
gtest_discover_tests(model_build_test DISCOVERY_TIMEOUT 60)
add_executable(scene_build_test scene_build_test.cc)
target_link_libraries(scene_build_test PRIVATE GTest::gtest_main slave_sim_lib)
gtest_discover_tests(scene_build_test DISCOVERY_TIMEOUT 60 WORKING_DIRECTORY ${PROJECT_SOURCE_DIR})

# The CLI: seed models written as glTF, built by `slave_sim inspect`, the second start from the
# cache; a malformed file gives a one-line error naming it.
set(HT_SEED_DIR ${CMAKE_BINARY_DIR}/seed_models)
add_test(NAME cli_seed_models_clean
  COMMAND ${CMAKE_COMMAND} -E rm -rf ${HT_SEED_DIR} ${CMAKE_BINARY_DIR}/cli_model_cache)
set_tests_properties(cli_seed_models_clean PROPERTIES FIXTURES_SETUP seed_clean)
add_test(NAME cli_seed_models_write
  COMMAND slave_sim seed-models --out ${HT_SEED_DIR} --model torus --model block)
set_tests_properties(cli_seed_models_write PROPERTIES FIXTURES_REQUIRED seed_clean
  FIXTURES_SETUP seed_files PASS_REGULAR_EXPRESSION "torus: 128000 triangles")
add_test(NAME cli_inspect_builds
  COMMAND slave_sim inspect ${HT_SEED_DIR}/torus.json --cache-dir ${CMAKE_BINARY_DIR}/cli_model_cache)
set_tests_properties(cli_inspect_builds PROPERTIES FIXTURES_REQUIRED seed_files
  FIXTURES_SETUP seed_built PASS_REGULAR_EXPRESSION "\"from_cache\": false" TIMEOUT 300)
add_test(NAME cli_inspect_second_start_uses_cache
  COMMAND slave_sim inspect ${HT_SEED_DIR}/torus.json --cache-dir ${CMAKE_BINARY_DIR}/cli_model_cache)
set_tests_properties(cli_inspect_second_start_uses_cache PROPERTIES FIXTURES_REQUIRED seed_built
  PASS_REGULAR_EXPRESSION "\"from_cache\": true")
add_test(NAME cli_inspect_missing_file COMMAND slave_sim inspect ${CMAKE_BINARY_DIR}/no_such.glb --no-cache)
set_tests_properties(cli_inspect_missing_file PROPERTIES
  PASS_REGULAR_EXPRESSION "^slave_sim inspect: error: [^\n]*no_such.glb[^\n]*\n$")
add_test(NAME cli_inspect_truncated_file
  COMMAND slave_sim inspect ${PROJECT_SOURCE_DIR}/tests/data/truncated.glb --no-cache)
set_tests_properties(cli_inspect_truncated_file PROPERTIES
  PASS_REGULAR_EXPRESSION "slave_sim inspect: error: [^\n]*truncated.glb")

# Both processes on a real glTF scene with animations (skips when ../shared/data is absent).
add_test(NAME scene_file_loopback_milk_truck
  COMMAND ${CMAKE_CURRENT_SOURCE_DIR}/scene_file_loopback.sh ${CMAKE_BINARY_DIR}
          ${PROJECT_SOURCE_DIR}/../shared/data/gltf/draco_testdata_gltf/CesiumMilkTruck/glTF/CesiumMilkTruck.gltf
          ${CMAKE_BINARY_DIR}/scene_file_loopback)
set_tests_properties(scene_file_loopback_milk_truck PROPERTIES SKIP_RETURN_CODE 77 RUN_SERIAL TRUE
  TIMEOUT 180 PASS_REGULAR_EXPRESSION "scene file loopback: ok|skipped")
