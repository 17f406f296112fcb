# Device backends that load the vendor's own run-time library at Open (dlopen), so that nothing of
# the vendors' SDKs is needed to build: Force Dimension (DHD library) and OpenHaptics (HD library).
target_sources(master_station_lib PRIVATE
  ${CMAKE_CURRENT_SOURCE_DIR}/src/vendor_library.cc
  ${CMAKE_CURRENT_SOURCE_DIR}/src/force_dimension.cc
  ${CMAKE_CURRENT_SOURCE_DIR}/src/openhaptics.cc
)
target_link_libraries(master_station_lib PUBLIC ${CMAKE_DL_LIBS})
