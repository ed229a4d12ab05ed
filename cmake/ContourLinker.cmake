# Linker for every executable (build speed only: the same objects and libraries go in). Each test
# source is its own program (contour_add_gtests), so a build links ~100 programs against the
# static project libraries; in the sanitizer build (dev: -O0, full debug info) each is ~300 MB and
# GNU ld (bfd) spends most of the link time there (measured on unit_servo_loop_test: bfd 14-20 s,
# gold 14 s, lld 5.5-8 s, mold 3-5 s).
#   CONTOUR_LINKER=auto     mold if the compiler can use it, else lld, else the compiler's default
#   CONTOUR_LINKER=default  the compiler's default linker (no -fuse-ld)
#   CONTOUR_LINKER=<name>   -fuse-ld=<name> (bfd, gold, lld, mold), an error if it does not link
# mold comes from tools/deps.d/build-speed.list (Debian 12: mold 1.10).
set(CONTOUR_LINKER "auto" CACHE STRING "Linker: auto (mold, lld, default), default, or a -fuse-ld= name")
set_property(CACHE CONTOUR_LINKER PROPERTY STRINGS auto default mold lld gold bfd)

include(CheckLinkerFlag)
set(_contour_ld "")
if(CONTOUR_LINKER STREQUAL "auto")
  foreach(_ld IN ITEMS mold lld)
    check_linker_flag(CXX "-fuse-ld=${_ld}" CONTOUR_CAN_LINK_WITH_${_ld})
    if(CONTOUR_CAN_LINK_WITH_${_ld})
      set(_contour_ld ${_ld})
      break()
    endif()
  endforeach()
elseif(NOT CONTOUR_LINKER STREQUAL "default")
  check_linker_flag(CXX "-fuse-ld=${CONTOUR_LINKER}" CONTOUR_CAN_LINK_WITH_${CONTOUR_LINKER})
  if(NOT CONTOUR_CAN_LINK_WITH_${CONTOUR_LINKER})
    message(FATAL_ERROR "CONTOUR_LINKER=${CONTOUR_LINKER}: ${CMAKE_CXX_COMPILER} cannot link with -fuse-ld=${CONTOUR_LINKER}")
  endif()
  set(_contour_ld ${CONTOUR_LINKER})
endif()
if(_contour_ld)
  add_link_options(-fuse-ld=${_contour_ld})
  message(STATUS "Linker: -fuse-ld=${_contour_ld} (CONTOUR_LINKER=${CONTOUR_LINKER})")
else()
  message(STATUS "Linker: the compiler's default (CONTOUR_LINKER=${CONTOUR_LINKER})")
endif()
