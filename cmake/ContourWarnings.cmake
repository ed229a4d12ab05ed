# One INTERFACE target carries the warning set; the CI preset turns them into errors.
add_library(contour_warnings INTERFACE)
add_library(contour::warnings ALIAS contour_warnings)
target_compile_options(contour_warnings INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wconversion -Wold-style-cast -Wnon-virtual-dtor
  -Wdouble-promotion
  $<$<BOOL:${CONTOUR_WERROR}>:-Werror>)
# g++ 12 (Debian 12 ships 12.2) at -O3 reports -Wrestrict inside libstdc++ for `"text" +
# std::string&&` (basic_string::insert -> memcpy "may overlap up to 9223372036854775813 bytes"):
# a false positive (no string here is near that size; g++ at -O2 and clang 14 do not warn). Off
# for the Release build type (-O3) with g++ < 13 only; the other build types keep the warning.
if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU" AND CMAKE_CXX_COMPILER_VERSION VERSION_LESS 13)
  target_compile_options(contour_warnings INTERFACE $<$<CONFIG:Release>:-Wno-restrict>)
endif()

# The compile settings every test program shares. Test sources get line tables only (-g1) in the
# build types with debug info: enough for a backtrace and an ASan report, and a quarter less
# compile time for the gtest-heavy sources (measured: 12 test sources at -j2, 56 s with -g, 43 s
# with -g1); the libraries and tools keep the full -g. (A shared precompiled header was tried:
# its 270 MB .gch made -j2 builds slower, 48-54 s against 32-37 s.)
function(contour_test_compile_settings tgt)
  target_include_directories(${tgt} PRIVATE ${PROJECT_SOURCE_DIR})
  target_compile_definitions(${tgt} PRIVATE CONTOUR_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
                             CONTOUR_BINARY_DIR="${PROJECT_BINARY_DIR}")
  target_compile_options(${tgt} PRIVATE $<$<CONFIG:Debug,RelWithDebInfo>:-g1>)
  # CONTOUR_TEST_OPT (the ci preset: -Og): the optimisation of the test programs' own sources,
  # after the build type's flag, so it wins. The product (libraries, contourd, the tools) keeps
  # the build type's; the unit tests are built at -O3 (ci-o3) and -O0 + sanitizers (dev) as well.
  # Measured on tests/unit/daemon/command_server_test.cpp: -O2 15.5 s, -Og 7.4 s of CPU.
  if(CONTOUR_TEST_OPT)
    target_compile_options(${tgt} PRIVATE ${CONTOUR_TEST_OPT})
  endif()
endfunction()

# contour_add_gtests(LABEL <label> LIBS <libs...> SOURCES <files...>)
# One executable per test source; tests are discovered at ctest time and carry the label.
# Target tests_<label> builds every test program of that label (and nothing else), so a build
# tree can run `ctest -L <label>` without building the tools: `cmake --build B --target tests_unit`.
function(contour_add_gtests)
  cmake_parse_arguments(A "" "LABEL;TIMEOUT" "LIBS;SOURCES" ${ARGN})
  if(NOT A_TIMEOUT)
    set(A_TIMEOUT 600)
  endif()
  foreach(src IN LISTS A_SOURCES)
    get_filename_component(name ${src} NAME_WE)
    set(tgt ${A_LABEL}_${name})
    add_executable(${tgt} ${src})
    if(NOT TARGET tests_${A_LABEL})
      add_custom_target(tests_${A_LABEL})
    endif()
    add_dependencies(tests_${A_LABEL} ${tgt})
    target_link_libraries(${tgt} PRIVATE ${A_LIBS} GTest::gtest GTest::gmock GTest::gtest_main
                          contour::warnings)
    contour_test_compile_settings(${tgt})
    # STATE_DIRECTORY: config/sim.yaml keeps its .var there (default /tmp): tests read a
    # directory of the build tree instead, never offsets a developer's daemon left in /tmp.
    file(MAKE_DIRECTORY ${PROJECT_BINARY_DIR}/test-state)
    gtest_discover_tests(${tgt} DISCOVERY_MODE PRE_TEST
                         PROPERTIES LABELS ${A_LABEL} TIMEOUT ${A_TIMEOUT}
                                    ENVIRONMENT STATE_DIRECTORY=${PROJECT_BINARY_DIR}/test-state
                         WORKING_DIRECTORY ${PROJECT_SOURCE_DIR})
  endforeach()
endfunction()
