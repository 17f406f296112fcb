# Novint Falcon backend: frames, firmware load, kinematics and the whole device against a fake
# FTDI transport that plays the Falcon's side; Open() through libusb where no Falcon is present.
add_executable(falcon_test ${CMAKE_CURRENT_SOURCE_DIR}/falcon_test.cc)
target_link_libraries(falcon_test PRIVATE GTest::gtest_main master_station_lib)
gtest_discover_tests(falcon_test DISCOVERY_TIMEOUT 60)
