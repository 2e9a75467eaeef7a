# Injected by scripts/build_interfaces.sh with -DCMAKE_PROJECT_INCLUDE; never used with a system ROS.
#
# The ROS wheels' exported *__rosidl_generator_py targets name the Python and numpy include
# directories of the machine that built the wheels (/opt/python/cp311-cp311/...), which do not
# exist here, and CMake refuses to generate a project that links an imported target with a
# missing include directory. Our own generator_py targets add this interpreter's Python and
# numpy include directories, so the stale entries are dropped, not replaced. Deferred to the end
# of the top-level CMakeLists.txt, when rosidl_generate_interfaces has imported every target.
function(_catheter_drop_missing_wheel_include_dirs)
  get_property(_targets DIRECTORY "${CMAKE_SOURCE_DIR}" PROPERTY IMPORTED_TARGETS)
  foreach(_target IN LISTS _targets)
    get_target_property(_dirs "${_target}" INTERFACE_INCLUDE_DIRECTORIES)
    if(NOT _dirs)
      continue()
    endif()
    set(_kept "")
    set(_dropped "")
    foreach(_dir IN LISTS _dirs)
      if(_dir MATCHES "^\\$<" OR EXISTS "${_dir}")
        list(APPEND _kept "${_dir}")
      else()
        list(APPEND _dropped "${_dir}")
      endif()
    endforeach()
    if(_dropped)
      message(STATUS "wheel fix-up: ${_target} drops missing include dirs ${_dropped}")
      set_property(TARGET "${_target}" PROPERTY INTERFACE_INCLUDE_DIRECTORIES "${_kept}")
    endif()
  endforeach()
endfunction()

cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}" CALL _catheter_drop_missing_wheel_include_dirs)
