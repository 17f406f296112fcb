# glTF scene loading against ../shared/data/gltf and files made in the temp dir.
add_executable(gltf_scene_test gltf_scene_test.cc)
target_link_libraries(gltf_scene_test PRIVATE GTest::gtest_main codecs)
gtest_discover_tests(gltf_scene_test DISCOVERY_TIMEOUT 60 WORKING_DIRECTORY ${PROJECT_SOURCE_DIR})
