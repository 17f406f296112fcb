# Installation (issue 16): `cmake --install build [--prefix P]` puts
#   bin/                      slave_sim, master_station, ht_relay, speed_error_frontier
#   lib/, include/haptic_core the haptic core (static library) and its public headers, with an
#                             exported CMake package: find_package(haptic_teleop CONFIG) gives
#                             haptic_teleop::haptic_core, and the demo models and scenes as
#                             haptic_teleop::haptic_demo_models (examples/contact_force)
#   lib/systemd/system/       the two services;  lib/udev/rules.d/  the device rules
#   share/haptic_teleop/      example configs, the plot scripts, the docs
# and `cpack -G DEB` (in the build folder) makes a Debian package of the same.
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

install(TARGETS slave_sim master_station speed_error_frontier
        RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
if(TARGET ht_relay)
  install(TARGETS ht_relay RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
endif()

install(TARGETS haptic_core haptic_demo_models EXPORT haptic_teleop_targets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
        INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(DIRECTORY ${PROJECT_SOURCE_DIR}/haptic_core/include/haptic_core
        DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
        PATTERN "model_build" EXCLUDE PATTERN "accuracy" EXCLUDE
        PATTERN "gpu_penetration_depth.h" EXCLUDE PATTERN "egl_context.h" EXCLUDE
        PATTERN "gl_program.h" EXCLUDE)
install(EXPORT haptic_teleop_targets NAMESPACE haptic_teleop::
        FILE haptic_teleopTargets.cmake
        DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/haptic_teleop)
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/haptic_teleopConfig.cmake.in
  ${CMAKE_CURRENT_BINARY_DIR}/haptic_teleopConfig.cmake
  INSTALL_DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/haptic_teleop)
write_basic_package_version_file(${CMAKE_CURRENT_BINARY_DIR}/haptic_teleopConfigVersion.cmake
  VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_CURRENT_BINARY_DIR}/haptic_teleopConfig.cmake
              ${CMAKE_CURRENT_BINARY_DIR}/haptic_teleopConfigVersion.cmake
        DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/haptic_teleop)

# The units name /usr/local/bin (a hand install); installed, they name where the binaries went
# (the prefix is read at install time, so `cpack` and `--prefix` both get it right).
foreach(unit haptic-master-station.service haptic-slave-sim.service)
  install(CODE "
    file(READ \"${PROJECT_SOURCE_DIR}/deploy/systemd/${unit}\" unit_text)
    string(REPLACE \"/usr/local/bin\" \"\${CMAKE_INSTALL_PREFIX}/${CMAKE_INSTALL_BINDIR}\"
           unit_text \"\${unit_text}\")
    set(unit_dir \"\$ENV{DESTDIR}\${CMAKE_INSTALL_PREFIX}/${CMAKE_INSTALL_LIBDIR}/systemd/system\")
    file(MAKE_DIRECTORY \"\${unit_dir}\")
    file(WRITE \"\${unit_dir}/${unit}\" \"\${unit_text}\")
    message(STATUS \"Installing: \${unit_dir}/${unit}\")")
endforeach()
install(FILES ${PROJECT_SOURCE_DIR}/deploy/udev/70-haptic-falcon.rules
              ${PROJECT_SOURCE_DIR}/deploy/udev/70-haptic-spacemouse.rules
              ${PROJECT_SOURCE_DIR}/deploy/udev/70-haptic-forcedimension.rules
        DESTINATION ${CMAKE_INSTALL_LIBDIR}/udev/rules.d)
install(FILES ${PROJECT_SOURCE_DIR}/deploy/config/operator.toml
              ${PROJECT_SOURCE_DIR}/deploy/config/remote.toml
        DESTINATION ${CMAKE_INSTALL_DATADIR}/haptic_teleop/config)
install(PROGRAMS ${PROJECT_SOURCE_DIR}/deploy/plot-frontier
                 ${PROJECT_SOURCE_DIR}/deploy/plot-stability-map
                 ${PROJECT_SOURCE_DIR}/deploy/report
        DESTINATION ${CMAKE_INSTALL_DATADIR}/haptic_teleop)
install(DIRECTORY ${PROJECT_SOURCE_DIR}/docs/ DESTINATION ${CMAKE_INSTALL_DATADIR}/haptic_teleop/docs)
install(FILES ${PROJECT_SOURCE_DIR}/README.md ${PROJECT_SOURCE_DIR}/deploy/TWO-MACHINES.md
        DESTINATION ${CMAKE_INSTALL_DATADIR}/haptic_teleop)

# Debian package: cpack -G DEB (in the build folder).
set(CPACK_GENERATOR "DEB")
set(CPACK_PACKAGE_NAME "haptic-teleop")
set(CPACK_PACKAGE_VERSION "${PROJECT_VERSION}")
set(CPACK_PACKAGE_CONTACT "haptic teleoperation team")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY
    "Networked 6-DoF haptic texture rendering: operator station and remote simulation node")
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PACKAGE_SECTION "science")
set(CPACK_PACKAGING_INSTALL_PREFIX "/usr")
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
include(CPack)
