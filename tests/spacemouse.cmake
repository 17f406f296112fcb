# SpaceMouse backend: the HID descriptor and report parsers fed the real descriptors and reports of
# ../shared/data/spacemouse (skipped with a message when absent), shaping, pose mapping, and
# Open() without a device.
add_executable(spacemouse_test spacemouse_test.cc)
target_link_libraries(spacemouse_test PRIVATE GTest::gtest_main master_station_lib)
gtest_discover_tests(spacemouse_test DISCOVERY_TIMEOUT 60 WORKING_DIRECTORY ${PROJECT_SOURCE_DIR})
