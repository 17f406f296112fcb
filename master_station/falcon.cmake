# Novint Falcon backend through libusb-1.0 (master_station/include/master_station/falcon.h and the
# headers it includes), one source per stage: FTDI transport, frame protocol, kinematics, device.
# Access to the device without root: deploy/udev/70-haptic-falcon.rules.
find_package(PkgConfig REQUIRED)
pkg_check_modules(LIBUSB REQUIRED IMPORTED_TARGET libusb-1.0)
target_sources(master_station_lib PRIVATE
  ${CMAKE_CURRENT_SOURCE_DIR}/src/falcon_ftdi.cc
  ${CMAKE_CURRENT_SOURCE_DIR}/src/falcon_protocol.cc
  ${CMAKE_CURRENT_SOURCE_DIR}/src/falcon_kinematics.cc
  ${CMAKE_CURRENT_SOURCE_DIR}/src/falcon.cc
)
target_link_libraries(master_station_lib PUBLIC PkgConfig::LIBUSB)
