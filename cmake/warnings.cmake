# Project-wide warning and sanitizer flags, applied per target by scanclean_add_library/_test.
option(SCANCLEAN_WERROR "Treat warnings as errors" OFF)
set(SCANCLEAN_SANITIZE "" CACHE STRING "Sanitizers to build with, e.g. address;undefined")

function(scanclean_set_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic)
  # GCC 12 reports false -Wrestrict errors inside libstdc++ for std::string concatenation at -O2+
  # (GCC bug 105329, fixed in GCC 13). Only that one warning is switched off, only on GCC 12.
  if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU" AND CMAKE_CXX_COMPILER_VERSION VERSION_LESS 13)
    target_compile_options(${target} PRIVATE -Wno-restrict)
  endif()
  if(SCANCLEAN_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
endfunction()

if(SCANCLEAN_SANITIZE)
  string(REPLACE ";" "," _scanclean_san "${SCANCLEAN_SANITIZE}")
  add_compile_options(-fsanitize=${_scanclean_san} -fno-omit-frame-pointer -fno-sanitize-recover=all)
  add_link_options(-fsanitize=${_scanclean_san})
endif()
