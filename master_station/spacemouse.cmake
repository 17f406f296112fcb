# 3Dconnexion SpaceMouse backend (hidapi, hidraw backend on Linux): descriptor and report parsers,
# pose mapping, and the SpaceMouseDevice. Debian 12: libhidapi-dev (hidapi 0.13.1).
find_package(PkgConfig REQUIRED)
pkg_check_modules(HIDAPI REQUIRED IMPORTED_TARGET hidapi-hidraw)
target_sources(master_station_lib PRIVATE
  ${CMAKE_CURRENT_SOURCE_DIR}/src/hid_descriptor.cc
  ${CMAKE_CURRENT_SOURCE_DIR}/src/spacemouse_report.cc
  ${CMAKE_CURRENT_SOURCE_DIR}/src/spacemouse_pose.cc
  ${CMAKE_CURRENT_SOURCE_DIR}/src/spacemouse.cc
)
target_link_libraries(master_station_lib PUBLIC PkgConfig::HIDAPI)
