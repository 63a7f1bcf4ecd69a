# SPDX-License-Identifier: BSD-3-Clause
# The Debian package and what it adds to `cmake --install` (packaging/):
#  - a man page per program, made at install time from its --help by help2man (imucal.1,
#    imucald.8, imucalctl.1; skipped with a warning when help2man is missing);
#  - bash completion for the three programs;
#  - the copyright file, the changelog and an example udev rule in the documentation folder.
# Then CPack's DEB generator: imucal_VERSION_ARCH.deb from everything the install puts in place
# but the camera backends, with packaging/debian/'s maintainer scripts and conffiles, and
# imucal-aravis_VERSION_ARCH.deb and imucal-libcamera_VERSION_ARCH.deb with those modules. `make package` builds it from a tree
# configured for /usr; `cpack --config BUILD/CPackConfig.cmake` packages any built tree (the unit's
# paths are set at install time, so the prefix the tree was configured with does not matter).
include(GNUInstallDirs)
set(IMUCAL_PACKAGING_DIR ${PROJECT_SOURCE_DIR}/packaging)
set(IMUCAL_PACKAGE_MAINTAINER "imucal maintainers <dev@imucal.invalid>"
    CACHE STRING "Maintainer field of the Debian package and its changelog")

find_program(IMUCAL_HELP2MAN help2man)
set(imucal_man_pages
    "$<TARGET_FILE:imucal>|imucal|1|calibrate MPU-6000 IMUs and camera-IMU rigs, offline tools"
    "$<TARGET_FILE:imucald>|imucald|8|the on-rig IMU and camera calibration service"
    "$<TARGET_FILE:imucalctl>|imucalctl|1|control and watch the imucald calibration service")
# Each page quoted on its own, for the foreach of the install code.
set(imucal_man_items "")
foreach(page IN LISTS imucal_man_pages)
  string(APPEND imucal_man_items " \"${page}\"")
endforeach()
if(NOT IMUCAL_HELP2MAN)
  install(CODE "message(WARNING \"help2man is not installed: no man pages (apt-get install help2man)\")"
          COMPONENT doc)
else()
  install(CODE "
    string(MD5 imucal_key \"\$ENV{DESTDIR}|\${CMAKE_INSTALL_PREFIX}\")
    set(imucal_gen \"${PROJECT_BINARY_DIR}/packaging/man-\${imucal_key}\")
    file(MAKE_DIRECTORY \"\${imucal_gen}\")
    foreach(page IN ITEMS ${imucal_man_items})
      string(REPLACE \"|\" \";\" page \"\${page}\")
      list(GET page 0 program)
      list(GET page 1 name)
      list(GET page 2 section)
      list(GET page 3 description)
      execute_process(
        COMMAND \"${IMUCAL_PACKAGING_DIR}/man/make-man.sh\" \"\${program}\" \${name} \${section}
                \"\${description}\" \"${IMUCAL_PACKAGING_DIR}/man/\${name}.h2m\" ${PROJECT_VERSION}
                \"\${imucal_gen}/\${name}.\${section}.gz\"
        COMMAND_ERROR_IS_FATAL ANY)
      file(INSTALL \"\${imucal_gen}/\${name}.\${section}.gz\"
           DESTINATION \"\${CMAKE_INSTALL_PREFIX}/${CMAKE_INSTALL_MANDIR}/man\${section}\")
    endforeach()
    file(REMOVE_RECURSE \"\${imucal_gen}\")" COMPONENT doc)
endif()

foreach(program imucal imucald imucalctl)
  install(FILES ${IMUCAL_PACKAGING_DIR}/completion/imucal.bash
          DESTINATION ${CMAKE_INSTALL_DATADIR}/bash-completion/completions RENAME ${program} COMPONENT doc)
endforeach()

configure_file(${IMUCAL_PACKAGING_DIR}/changelog.in ${PROJECT_BINARY_DIR}/packaging/changelog @ONLY)
# Compressed when configuring: the main package and each backend's install it on their own.
execute_process(COMMAND gzip -9nc ${PROJECT_BINARY_DIR}/packaging/changelog
                OUTPUT_FILE ${PROJECT_BINARY_DIR}/packaging/changelog.gz COMMAND_ERROR_IS_FATAL ANY)
install(FILES ${PROJECT_BINARY_DIR}/packaging/changelog.gz ${IMUCAL_PACKAGING_DIR}/copyright
        DESTINATION ${CMAKE_INSTALL_DOCDIR} COMPONENT doc)
install(FILES ${IMUCAL_PACKAGING_DIR}/60-imucal-devices.rules
        DESTINATION ${CMAKE_INSTALL_DOCDIR}/examples COMPONENT doc)
# Each camera backend's package has the copyright and changelog in its own documentation folder.
foreach(backend aravis libcamera)
  install(FILES ${PROJECT_BINARY_DIR}/packaging/changelog.gz ${IMUCAL_PACKAGING_DIR}/copyright
          DESTINATION ${CMAKE_INSTALL_DATADIR}/doc/imucal-${backend} COMPONENT ${backend})
endforeach()

# CPack, DEB generator.
set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME imucal)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_CONTACT "${IMUCAL_PACKAGE_MAINTAINER}")
set(CPACK_DEBIAN_PACKAGE_MAINTAINER "${IMUCAL_PACKAGE_MAINTAINER}")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "IMU and camera-IMU calibration on the rig")
set(CPACK_PACKAGE_DESCRIPTION
    "imucal calibrates rigs that carry an InvenSense MPU-6000 IMU and cameras, on
the rig itself: it records the IMU and the cameras on one clock, estimates the
IMU intrinsics (multi-position static method) and the camera-IMU calibration,
and writes the result to the rig's storage (file, nvmem or I2C EEPROM).

The package holds the offline tool imucal, the service imucald with its
systemd unit (installed, neither enabled nor started) and its client
imucalctl, the operator's console. The rig configuration is
/etc/imucal/rig.yaml.")
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
# Installed as `cmake --install` with DESTDIR, so the absolute paths (/etc/imucal, the unit's
# folder) land in the package and the install code sees the prefix /usr.
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_SET_DESTDIR ON)
set(CPACK_INSTALL_PREFIX /usr)
set(CPACK_STRIP_FILES ON)
# Three packages: imucal (the programs, the solver, camera, renderer and virtual-rig modules, the
# unit, docs) and one per camera backend, imucal-aravis and imucal-libcamera, whose libraries a
# rig without such a camera does not need (Aravis and libcamera pull in GStreamer, udev and
# more). The service names the package when a configured camera needs a module that is not
# installed (app/module_loader.cpp).
set(CPACK_DEB_COMPONENT_INSTALL ON)
set(CPACK_COMPONENTS_GROUPING ONE_PER_GROUP)
set(CPACK_COMPONENTS_ALL service doc aravis libcamera)
# Depends: the libraries' packages (dpkg-shlibdeps, from dpkg-dev), per package; systemd for the
# unit, sysusers.d and tmpfiles.d.
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_MAIN_PACKAGE_NAME imucal)
set(CPACK_DEBIAN_MAIN_PACKAGE_DEPENDS "systemd")
# gnuplot draws the figures of the reports (imucal report, and the report of every service
# session). Suggested, not recommended: apt follows its recommends (groff, then ghostscript,
# imagemagick, perl) to 123 packages and 249 MB on a rig, where --no-install-recommends takes 45
# and 64 MB (docs/service.md, "Installing"). i2c-tools brings the udev rule that gives /dev/i2c-N
# to group i2c.
set(CPACK_DEBIAN_MAIN_PACKAGE_SUGGESTS "gnuplot-nox, i2c-tools, imucal-aravis, imucal-libcamera")
set(CPACK_DEBIAN_MAIN_PACKAGE_CONTROL_EXTRA
    ${IMUCAL_PACKAGING_DIR}/debian/conffiles ${IMUCAL_PACKAGING_DIR}/debian/postinst
    ${IMUCAL_PACKAGING_DIR}/debian/prerm ${IMUCAL_PACKAGING_DIR}/debian/postrm)
# CPack puts CPACK_PACKAGE_DESCRIPTION_SUMMARY before every package's description (its synopsis).
set(CPACK_DEBIAN_MAIN_DESCRIPTION "${CPACK_PACKAGE_DESCRIPTION}")
foreach(backend aravis libcamera)
  string(TOUPPER ${backend} upper)
  set(CPACK_DEBIAN_${upper}_PACKAGE_NAME imucal-${backend})
  set(CPACK_DEBIAN_${upper}_PACKAGE_DEPENDS "imucal (= ${PROJECT_VERSION})")
endforeach()
set(CPACK_DEBIAN_ARAVIS_DESCRIPTION
    "The GenICam camera backend of imucal: the module through which imucal's service\nand tools read GigE Vision and USB3 Vision cameras with Aravis. Install it on a\nrig whose configuration names an aravis camera.")
set(CPACK_DEBIAN_LIBCAMERA_DESCRIPTION
    "The libcamera backend of imucal: the module through which imucal's service and\ntools read cameras with libcamera (Raspberry Pi cameras and other CSI-2\nsensors). Install it on a rig whose configuration names a libcamera camera.")
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION ON)
include(CPack)
cpack_add_component_group(main)
cpack_add_component(service GROUP main)
cpack_add_component(doc GROUP main)
cpack_add_component(aravis)
cpack_add_component(libcamera)
