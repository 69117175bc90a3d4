# FindOpenNI2: Debian's libopenni2-dev through pkg-config; defines the imported target OpenNI2::OpenNI2
# and OpenNI2_LIBRARY (the resolved libOpenNI2.so.0 path) and OpenNI2_DRIVER_DIR (system driver folder).
find_package(PkgConfig QUIET)
if(PkgConfig_FOUND)
  pkg_check_modules(PC_OPENNI2 QUIET libopenni2)
endif()
find_path(OpenNI2_INCLUDE_DIR OpenNI.h HINTS ${PC_OPENNI2_INCLUDE_DIRS} PATH_SUFFIXES openni2)
find_library(OpenNI2_LIBRARY NAMES OpenNI2 HINTS ${PC_OPENNI2_LIBRARY_DIRS})
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(OpenNI2 REQUIRED_VARS OpenNI2_LIBRARY OpenNI2_INCLUDE_DIR)
if(OpenNI2_FOUND)
  get_filename_component(_oni_real "${OpenNI2_LIBRARY}" REALPATH)
  get_filename_component(OpenNI2_LIBRARY_DIR "${_oni_real}" DIRECTORY)
  set(OpenNI2_DRIVER_DIR "${OpenNI2_LIBRARY_DIR}/OpenNI2/Drivers")
  if(NOT TARGET OpenNI2::OpenNI2)
    add_library(OpenNI2::OpenNI2 UNKNOWN IMPORTED)
    set_target_properties(OpenNI2::OpenNI2 PROPERTIES
      IMPORTED_LOCATION "${OpenNI2_LIBRARY}"
      INTERFACE_INCLUDE_DIRECTORIES "${OpenNI2_INCLUDE_DIR}")
  endif()
endif()
mark_as_advanced(OpenNI2_INCLUDE_DIR OpenNI2_LIBRARY)
