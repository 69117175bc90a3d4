# scanclean_package.cmake: included once, last, by the top CMakeLists.txt, after every module.
# Writes the install rules that are not per library (program, OpenNI2 driver folder), the CMake
# package config (find_package(scanclean) -> scanclean::<module>, dependencies through
# find_dependency), one pkg-config file per module plus scanclean.pc, and the CPack DEB setup.
#
# Libraries are static archives (PIC): the program and the Python module are self-contained, and
# there is no shared-library ABI (SONAME, symbols file) to maintain for a 0.x API. Consumers
# therefore link the libraries' private dependencies too; the package config finds them
# (find_dependency) and the pkg-config files list them in Requires.
include(CMakePackageConfigHelpers)

get_property(_sc_modules GLOBAL PROPERTY SCANCLEAN_MODULES)
# pkg-config files are relocatable: prefix=${pcfiledir}/<this>.
file(RELATIVE_PATH SC_PC_PREFIX_FROM_PCDIR "/p/${CMAKE_INSTALL_LIBDIR}/pkgconfig" "/p")

# --- Dependencies of the exported libraries ------------------------------------------------------
# Every link item of every module, mapped to a find_dependency() line (CMake) and to a pkg-config
# module or a linker flag. Unknown Foo::Bar targets fall back to find_dependency(Foo).
set(_sc_find "")
set(_sc_opencv_components "")
foreach(m ${_sc_modules})
  set(_pc_requires "")
  set(_pc_libs "")
  get_target_property(_deps scanclean_${m} LINK_LIBRARIES)
  if(NOT _deps)
    set(_deps "")
  endif()
  foreach(dep ${_deps})
    set(_find "")
    set(_pc "")
    set(_flag "")
    if(dep MATCHES "^scanclean::(.+)$")
      set(_pc "scanclean-${CMAKE_MATCH_1}")
    elseif(dep MATCHES "^scanclean_(.+)$")
      set(_pc "scanclean-${CMAKE_MATCH_1}")
    elseif(dep MATCHES "^opencv_(.+)$")
      list(APPEND _sc_opencv_components ${CMAKE_MATCH_1})
      set(_pc opencv4)
    elseif(dep MATCHES "^Eigen3::")
      set(_find "find_dependency(Eigen3 3.3 NO_MODULE)")
      set(_pc eigen3)
    elseif(dep MATCHES "^nlohmann_json::")
      set(_find "find_dependency(nlohmann_json 3)")
      set(_pc nlohmann_json)
    elseif(dep MATCHES "^TBB::")
      set(_find "find_dependency(TBB)")
      set(_pc tbb)
    elseif(dep MATCHES "^nanoflann::")
      set(_find "find_dependency(nanoflann)")
      set(_pc nanoflann)
    elseif(dep MATCHES "^hwy::")
      set(_find "find_dependency(hwy)")
      set(_pc libhwy)
    elseif(dep MATCHES "^liblzf::")
      set(_find "find_dependency(liblzf)")
      set(_pc liblzf)
    elseif(dep MATCHES "^OpenNI2::")
      set(_find "find_dependency(OpenNI2)")
      set(_pc libopenni2)
    elseif(dep MATCHES "^Threads::")
      set(_find "find_dependency(Threads)")
      set(_flag "-pthread")
    elseif(dep MATCHES "^PkgConfig::(.+)$")
      set(_prefix ${CMAKE_MATCH_1})
      set(_module ${_prefix})
      if(_prefix STREQUAL "libusb")
        set(_module libusb-1.0)
      elseif(${_prefix}_MODULE_NAME)
        set(_module ${${_prefix}_MODULE_NAME})
      endif()
      set(_find "find_dependency(PkgConfig)\npkg_check_modules(${_prefix} REQUIRED QUIET IMPORTED_TARGET ${_module})")
      set(_pc ${_module})
    elseif(dep MATCHES "^([A-Za-z0-9_]+)::")
      set(_find "find_dependency(${CMAKE_MATCH_1})")
    elseif(dep MATCHES "^-")
      set(_flag "${dep}")
    elseif(NOT TARGET ${dep})
      set(_flag "-l${dep}")
    endif()
    if(_find)
      string(FIND "${_sc_find}" "${_find}\n" _pos)
      if(_pos EQUAL -1)
        string(APPEND _sc_find "${_find}\n")
      endif()
    endif()
    if(_pc)
      list(APPEND _pc_requires ${_pc})
    endif()
    if(_flag)
      list(APPEND _pc_libs ${_flag})
    endif()
  endforeach()
  list(REMOVE_DUPLICATES _pc_requires)
  list(REMOVE_DUPLICATES _pc_libs)
  string(REPLACE ";" ", " SC_PC_REQUIRES "${_pc_requires}")
  string(REPLACE ";" " " SC_PC_LIBS "${_pc_libs}")
  set(SC_PC_NAME "scanclean-${m}")
  set(SC_PC_DESCRIPTION "scanclean ${m} module (static library)")
  set(SC_PC_LIB "-lscanclean_${m}")
  configure_file(${PROJECT_SOURCE_DIR}/cmake/scanclean.pc.in
    ${PROJECT_BINARY_DIR}/pkgconfig/scanclean-${m}.pc @ONLY)
  install(FILES ${PROJECT_BINARY_DIR}/pkgconfig/scanclean-${m}.pc
    DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig COMPONENT dev)
endforeach()
if(_sc_opencv_components)
  list(REMOVE_DUPLICATES _sc_opencv_components)
  string(REPLACE ";" " " _comps "${_sc_opencv_components}")
  string(APPEND _sc_find "find_dependency(OpenCV 4 COMPONENTS ${_comps})\n")
endif()
set(SCANCLEAN_FIND_DEPENDENCIES "${_sc_find}")
# The umbrella pkg-config file: every module.
set(SC_PC_NAME "scanclean")
set(SC_PC_DESCRIPTION "${PROJECT_DESCRIPTION} (every module)")
set(SC_PC_LIB "")
set(SC_PC_LIBS "")
list(TRANSFORM _sc_modules PREPEND "scanclean-" OUTPUT_VARIABLE _all)
string(REPLACE ";" ", " SC_PC_REQUIRES "${_all}")
configure_file(${PROJECT_SOURCE_DIR}/cmake/scanclean.pc.in ${PROJECT_BINARY_DIR}/pkgconfig/scanclean.pc
  @ONLY)
install(FILES ${PROJECT_BINARY_DIR}/pkgconfig/scanclean.pc
  DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig COMPONENT dev)

# --- CMake package config --------------------------------------------------------------------------
set(SCANCLEAN_MODULE_LIST "${_sc_modules}")
install(EXPORT scanclean-targets NAMESPACE scanclean:: DESTINATION ${SCANCLEAN_INSTALL_CMAKEDIR}
  COMPONENT dev)
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/scanclean-config.cmake.in
  ${PROJECT_BINARY_DIR}/scanclean-config.cmake
  INSTALL_DESTINATION ${SCANCLEAN_INSTALL_CMAKEDIR}
  PATH_VARS SCANCLEAN_INSTALL_ONIDIR)
write_basic_package_version_file(${PROJECT_BINARY_DIR}/scanclean-config-version.cmake
  COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/scanclean-config.cmake
  ${PROJECT_BINARY_DIR}/scanclean-config-version.cmake ${PROJECT_SOURCE_DIR}/cmake/FindOpenNI2.cmake
  DESTINATION ${SCANCLEAN_INSTALL_CMAKEDIR} COMPONENT dev)

# --- The program and its OpenNI2 driver folder ----------------------------------------------------
# Installed layout: bin/scanclean with RUNPATH $ORIGIN/../<onidir>, where <onidir> holds
#   libOpenNI2.so.0 -> the system library (OpenNI2 loads drivers from <its folder>/OpenNI2/Drivers)
#   OpenNI2/Drivers/libScancleanVirtualSensor.so.0 (the project's plugin), PS1080.ini and links to
#   Debian's libOniFile.so.0 (.oni player), libPS1080.so.0 and libPSLink.so.0 (live sensors).
# No LD_LIBRARY_PATH, no edit of /etc/openni2; the build tree keeps <build>/oni (BUILD_RPATH).
if(TARGET scanclean)
  file(RELATIVE_PATH _bin_to_oni "/p/${CMAKE_INSTALL_BINDIR}" "/p/${SCANCLEAN_INSTALL_ONIDIR}")
  set_target_properties(scanclean PROPERTIES INSTALL_RPATH "$ORIGIN/${_bin_to_oni}")
  install(TARGETS scanclean RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR} COMPONENT runtime)
endif()
if(TARGET scanclean_vsensor)
  set(_oni_drivers "${SCANCLEAN_INSTALL_ONIDIR}/OpenNI2/Drivers")
  install(TARGETS scanclean_vsensor LIBRARY DESTINATION ${_oni_drivers} COMPONENT runtime)
  install(FILES ${PROJECT_SOURCE_DIR}/drivers/openni2_vsensor/PS1080.ini
    DESTINATION ${_oni_drivers} COMPONENT runtime)
  set(_links "libOpenNI2.so.0=${OpenNI2_LIBRARY_DIR}/libOpenNI2.so.0")
  foreach(drv OniFile PS1080 PSLink)
    list(APPEND _links
      "OpenNI2/Drivers/lib${drv}.so.0=${OpenNI2_DRIVER_DIR}/lib${drv}.so.0")
  endforeach()
  # Links to the system files: relative when the system file lies under the install prefix (the
  # .deb, prefix /usr), absolute otherwise (a scratch prefix).
  install(CODE "
    foreach(_pair ${_links})
      string(REPLACE \"=\" \";\" _pair \"\${_pair}\")
      list(GET _pair 0 _name)
      list(GET _pair 1 _target)
      set(_link \"\${CMAKE_INSTALL_PREFIX}/${SCANCLEAN_INSTALL_ONIDIR}/\${_name}\")
      string(FIND \"\${_target}\" \"\${CMAKE_INSTALL_PREFIX}/\" _pos)
      if(_pos EQUAL 0)
        get_filename_component(_dir \"\${_link}\" DIRECTORY)
        file(RELATIVE_PATH _target \"\${_dir}\" \"\${_target}\")
      endif()
      message(STATUS \"Installing: \${_link} -> \${_target}\")
      get_filename_component(_dir \"\$ENV{DESTDIR}\${_link}\" DIRECTORY)
      file(MAKE_DIRECTORY \"\${_dir}\")
      file(CREATE_LINK \"\${_target}\" \"\$ENV{DESTDIR}\${_link}\" SYMBOLIC)
    endforeach()" COMPONENT runtime)
endif()

# --- Licence, Debian copyright file, manual page -------------------------------------------------
# /usr/share/doc/<package>/copyright for both packages (Debian policy 12.5; it holds the text
# of LICENSE), and scanclean(1) (packaging/scanclean.1, gzipped as Debian wants it).
foreach(_pkg_comp "scanclean;runtime" "scanclean-dev;dev")
  list(GET _pkg_comp 0 _pkg)
  list(GET _pkg_comp 1 _comp)
  install(FILES ${PROJECT_SOURCE_DIR}/packaging/copyright
    DESTINATION ${CMAKE_INSTALL_DATAROOTDIR}/doc/${_pkg} COMPONENT ${_comp})
endforeach()
find_program(SCANCLEAN_GZIP gzip)
if(SCANCLEAN_GZIP)
  add_custom_command(OUTPUT ${PROJECT_BINARY_DIR}/scanclean.1.gz
    COMMAND ${SCANCLEAN_GZIP} -n -9 -c ${PROJECT_SOURCE_DIR}/packaging/scanclean.1
            > ${PROJECT_BINARY_DIR}/scanclean.1.gz
    DEPENDS ${PROJECT_SOURCE_DIR}/packaging/scanclean.1 VERBATIM)
  add_custom_target(scanclean_manpage ALL DEPENDS ${PROJECT_BINARY_DIR}/scanclean.1.gz)
  install(FILES ${PROJECT_BINARY_DIR}/scanclean.1.gz
    DESTINATION ${CMAKE_INSTALL_MANDIR}/man1 COMPONENT runtime)
endif()

# --- Debian package (cpack -G DEB in the build folder) ---------------------------------------------
# Two packages: scanclean (program, driver folder, Python module; runtime dependencies found by
# dpkg-shlibdeps) and scanclean-dev (headers, static libraries, CMake config, pkg-config files;
# depends on the -dev packages the package config finds).
set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME scanclean)
set(CPACK_PACKAGE_VENDOR "scanclean")
set(CPACK_PACKAGE_CONTACT "scanclean maintainers <scanclean@example.org>")
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_DEB_COMPONENT_INSTALL ON)
set(CPACK_STRIP_FILES ON)
set(CPACK_COMPONENTS_ALL runtime dev)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
set(CPACK_DEBIAN_RUNTIME_PACKAGE_NAME scanclean)
set(CPACK_DEBIAN_RUNTIME_PACKAGE_SHLIBDEPS ON)
# Not found by dpkg-shlibdeps: the Python module's interpreter (pybind11 modules are built for one
# Python minor version) and numpy. libopenni2-0 (with the PS1080/OniFile drivers the driver folder
# links to) comes from dpkg-shlibdeps, as the program links libOpenNI2.so.0.
set(_runtime_depends "")
if(TARGET scanclean_python)
  list(APPEND _runtime_depends "python3 (>= ${SCANCLEAN_PYTHON_VERSION})"
    "python3 (<< ${SCANCLEAN_PYTHON_NEXT})" python3-numpy)
endif()
string(REPLACE ";" ", " CPACK_DEBIAN_RUNTIME_PACKAGE_DEPENDS "${_runtime_depends}")
# Descriptions: the synopsis is PROJECT_DESCRIPTION (CPack prepends it); lines of at most 80.
set(CPACK_COMPONENT_RUNTIME_DESCRIPTION "The scanclean program cleans scanner output with the robust filter of
Schall, Belyaev and Seidel (2005): point-cloud files (PLY, PCD, XYZ,
Stanford .conf), live OpenNI2 depth sensors, .oni files, recordings,
depth images and Gray-code structured light. Includes the Python module
(import scanclean).")
set(CPACK_DEBIAN_DEV_PACKAGE_NAME scanclean-dev)
set(CPACK_DEBIAN_DEV_PACKAGE_SECTION libdevel)
set(CPACK_DEBIAN_DEV_PACKAGE_DEPENDS
  "scanclean (= ${PROJECT_VERSION}), libeigen3-dev, libnanoflann-dev, libtbb-dev, libhwy-dev, nlohmann-json3-dev, liblzf-dev, libopencv-dev, libopencv-contrib-dev, libopenni2-dev, libusb-1.0-0-dev, pkg-config")
set(CPACK_COMPONENT_DEV_DESCRIPTION "Development files of the scanclean libraries (robust filter, point-cloud
I/O, recordings, range sources, capture pipeline): headers, static
libraries, the CMake package config (find_package(scanclean)) and
pkg-config files.")
include(CPack)
