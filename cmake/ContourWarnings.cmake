# One INTERFACE target carries the warning set; the CI preset turns them into errors.
add_library(contour_warnings INTERFACE)
add_library(contour::warnings ALIAS contour_warnings)
target_compile_options(contour_warnings INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wconversion -Wold-style-cast -Wnon-virtual-dtor
  -Wdouble-promotion
  $<$<BOOL:${CONTOUR_WERROR}>:-Werror>)

# contour_add_gtests(LABEL <label> LIBS <libs...> SOURCES <files...>)
# One executable per test source; tests are discovered at ctest time and carry the label.
function(contour_add_gtests)
  cmake_parse_arguments(A "" "LABEL;TIMEOUT" "LIBS;SOURCES" ${ARGN})
  if(NOT A_TIMEOUT)
    set(A_TIMEOUT 600)
  endif()
  foreach(src IN LISTS A_SOURCES)
    get_filename_component(name ${src} NAME_WE)
    set(tgt ${A_LABEL}_${name})
    add_executable(${tgt} ${src})
    target_link_libraries(${tgt} PRIVATE ${A_LIBS} GTest::gtest GTest::gmock GTest::gtest_main
                          contour::warnings)
    target_include_directories(${tgt} PRIVATE ${PROJECT_SOURCE_DIR})
    target_compile_definitions(${tgt} PRIVATE CONTOUR_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
                               CONTOUR_BINARY_DIR="${PROJECT_BINARY_DIR}")
    gtest_discover_tests(${tgt} DISCOVERY_MODE PRE_TEST
                         PROPERTIES LABELS ${A_LABEL} TIMEOUT ${A_TIMEOUT}
                         WORKING_DIRECTORY ${PROJECT_SOURCE_DIR})
  endforeach()
endfunction()
