# scanclean_add_library(NAME <name> SOURCES ... [PUBLIC_DEPS ...] [PRIVATE_DEPS ...])
# Creates target scanclean_<name> with alias scanclean::<name>; headers live in <dir>/include.
# Every library is also installed (static archive, public headers), exported as scanclean::<name>
# to the CMake package config and described by a pkg-config file scanclean-<name>.pc; the package
# itself (config, version file, pkg-config files, CPack) is written by scanclean_package.cmake
# once every module has been added.
include(GNUInstallDirs)

function(scanclean_add_library)
  cmake_parse_arguments(ARG "" "NAME" "SOURCES;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  set(target scanclean_${ARG_NAME})
  add_library(${target} STATIC ${ARG_SOURCES})
  add_library(scanclean::${ARG_NAME} ALIAS ${target})
  target_include_directories(${target} PUBLIC
    $<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include> $<INSTALL_INTERFACE:include>)
  target_link_libraries(${target} PUBLIC ${ARG_PUBLIC_DEPS} PRIVATE ${ARG_PRIVATE_DEPS})
  set_target_properties(${target} PROPERTIES POSITION_INDEPENDENT_CODE ON EXPORT_NAME ${ARG_NAME})
  scanclean_set_warnings(${target})

  install(TARGETS ${target} EXPORT scanclean-targets
    ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT dev)
  if(EXISTS ${CMAKE_CURRENT_SOURCE_DIR}/include)
    install(DIRECTORY ${CMAKE_CURRENT_SOURCE_DIR}/include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
      COMPONENT dev)
  endif()
  # Listed for scanclean_package.cmake (find_dependency lines, pkg-config files), which reads
  # each target's final LINK_LIBRARIES, so deps added after this call are included too.
  set_property(GLOBAL APPEND PROPERTY SCANCLEAN_MODULES ${ARG_NAME})
endfunction()

# Install layout (relative to the prefix). The program finds its OpenNI2 driver folder through
# RUNPATH $ORIGIN/../${SCANCLEAN_INSTALL_ONIDIR} (scanclean_package.cmake), so an installed tree
# can be moved as a whole.
set(SCANCLEAN_INSTALL_CMAKEDIR "${CMAKE_INSTALL_LIBDIR}/cmake/scanclean" CACHE STRING
  "Install folder of the CMake package config (relative to the prefix)")
set(SCANCLEAN_INSTALL_ONIDIR "${CMAKE_INSTALL_LIBDIR}/scanclean/oni" CACHE STRING
  "Install folder of the private OpenNI2 driver folder (relative to the prefix)")
set(SCANCLEAN_INSTALL_PYTHONDIR "lib/python3/dist-packages" CACHE STRING
  "Install folder of the Python module (relative to the prefix; Debian's layout)")

# scanclean_use_modules(<target> <PUBLIC|PRIVATE|DEFINE_ONLY> <module>...)
# For each module built in this tree (target scanclean::<module> exists): links it with the given
# scope (not with DEFINE_ONLY) and defines SCANCLEAN_HAVE_<MODULE>=1 for the target's own sources.
# Modules absent from the build are skipped, so the sources compile without them.
function(scanclean_use_modules target scope)
  foreach(lib ${ARGN})
    if(TARGET scanclean::${lib})
      if(NOT scope STREQUAL "DEFINE_ONLY")
        target_link_libraries(${target} ${scope} scanclean::${lib})
      endif()
      string(TOUPPER ${lib} LIB)
      target_compile_definitions(${target} PRIVATE SCANCLEAN_HAVE_${LIB}=1)
    endif()
  endforeach()
endfunction()
