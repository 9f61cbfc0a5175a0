# The Debian package: `cpack -G DEB` in a build directory, or scripts/package (a Release build, lintian, the install
# test). It holds what `cmake --install --prefix /usr` installs (the program, the unit, the example configuration,
# the docs and copyright) and, from the component `deb` that a plain `cmake --install` leaves out, the drop-in that
# runs the unit as the system user the maintainer scripts create, the manual page and the Debian changelog.
# docs/operations.md, "Debian package".
install(FILES ${CMAKE_CURRENT_LIST_DIR}/imubridge.service.d/system-user.conf
        DESTINATION lib/systemd/system/imubridge.service.d COMPONENT deb EXCLUDE_FROM_ALL)
# The manual page and the Debian changelog, with this version, compressed as Debian wants them (gzip -9n: no name or
# time inside, so the same sources give the same bytes).
foreach(file imubridge.1 changelog.Debian)
  configure_file(${CMAKE_CURRENT_LIST_DIR}/${file} ${CMAKE_BINARY_DIR}/deb/${file} @ONLY)
  execute_process(COMMAND gzip -9n -c ${CMAKE_BINARY_DIR}/deb/${file} OUTPUT_FILE ${CMAKE_BINARY_DIR}/deb/${file}.gz
                  COMMAND_ERROR_IS_FATAL ANY)
endforeach()
install(FILES ${CMAKE_BINARY_DIR}/deb/imubridge.1.gz DESTINATION share/man/man1 COMPONENT deb EXCLUDE_FROM_ALL)
install(FILES ${CMAKE_BINARY_DIR}/deb/changelog.Debian.gz DESTINATION share/doc/imubridge RENAME changelog.gz
        COMPONENT deb EXCLUDE_FROM_ALL)

set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME imubridge)
set(CPACK_PACKAGE_VENDOR "imubridge developers")
set(CPACK_PACKAGE_CONTACT "imubridge developers <dev@imubridge.invalid>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "quadrotor IMU ground-station daemon")
set(CPACK_PACKAGE_DESCRIPTION [[
imubridge reads IMU streams from serial links (direct UART/USB, XBee API
frames over radio, or MAVLink) and records every raw byte and every decoded
sample in SQLite without losing any. It estimates the vehicle's horizontal
velocity live from a drag model of the accelerometer, identifies that model
from flight data, imports EuRoC, PX4 ULog and MAVLink telemetry logs, and
replays recorded sessions through the same pipeline.
.
This package runs it as a systemd service (imubridge.service) under its own
system user, recording into /var/lib/imubridge.]])
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)  # imubridge_0.1.0_amd64.deb
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
# The shared libraries' packages come from dpkg-shlibdeps; adduser is for postinst, procps for the unit's
# ExecReload (/bin/kill), which a minimal Debian lacks.
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PACKAGE_DEPENDS "adduser, procps")
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA
    ${CMAKE_CURRENT_LIST_DIR}/postinst ${CMAKE_CURRENT_LIST_DIR}/prerm ${CMAKE_CURRENT_LIST_DIR}/postrm
    ${CMAKE_CURRENT_LIST_DIR}/conffiles)
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION ON)
set(CPACK_DEBIAN_COMPRESSION_TYPE xz)
set(CPACK_STRIP_FILES ON)
# Installed as to the prefix /usr under a staging DESTDIR, so the install rules put the configuration in /etc and
# write the unit's paths as the installed system sees them.
set(CPACK_SET_DESTDIR ON)
set(CPACK_INSTALL_PREFIX /usr)
# Packaging takes the program as it is built and builds nothing: the test suite packages its build directory while
# other tests run (without this, cpack's "preinstall" step would make every target first). `cmake --install` never
# builds anyway.
set(CMAKE_SKIP_INSTALL_ALL_DEPENDENCY ON)
set(CPACK_INSTALL_CMAKE_PROJECTS "${CMAKE_BINARY_DIR};imubridge;ALL;/;${CMAKE_BINARY_DIR};imubridge;deb;/")
include(CPack)
