# Work around a defect of the ROS 2 PyPI wheels (see README, "Building from wheels").
#
# The exported CMake targets of wheel-installed message packages (for example
# std_msgs::std_msgs__rosidl_generator_py) list the wheel builder's Python include directory
# (/opt/python/cp311-cp311/include/python3.11) in INTERFACE_INCLUDE_DIRECTORIES. CMake refuses to
# generate a build system when an imported target names a directory that does not exist.
#
# Injected with -DCMAKE_PROJECT_INCLUDE=<this file> (colcon: --cmake-args), this file defers a
# function to the end of the configure step; it then removes non-existent directories from the
# include directories of every imported target, so the package's own CMakeLists.txt stays standard.
# Generator expressions and existing directories are kept unchanged.

if(COMMAND _rimd_drop_missing_includes)
  return()
endif()

function(_rimd_collect_imported_targets dir out_var)
  get_property(targets DIRECTORY "${dir}" PROPERTY IMPORTED_TARGETS)
  get_property(subdirs DIRECTORY "${dir}" PROPERTY SUBDIRECTORIES)
  foreach(sub IN LISTS subdirs)
    _rimd_collect_imported_targets("${sub}" sub_targets)
    list(APPEND targets ${sub_targets})
  endforeach()
  set(${out_var} "${targets}" PARENT_SCOPE)
endfunction()

function(_rimd_drop_missing_includes)
  _rimd_collect_imported_targets("${CMAKE_SOURCE_DIR}" targets)
  set(dropped "")
  foreach(target IN LISTS targets)
    get_target_property(type ${target} TYPE)
    get_target_property(dirs ${target} INTERFACE_INCLUDE_DIRECTORIES)
    if(NOT dirs)
      continue()
    endif()
    set(kept "")
    set(changed FALSE)
    foreach(dir IN LISTS dirs)
      if(dir MATCHES "^\\$<" OR EXISTS "${dir}")
        list(APPEND kept "${dir}")
      else()
        set(changed TRUE)
        list(APPEND dropped "${dir}")
      endif()
    endforeach()
    if(changed)
      set_property(TARGET ${target} PROPERTY INTERFACE_INCLUDE_DIRECTORIES "${kept}")
    endif()
  endforeach()
  if(dropped)
    list(REMOVE_DUPLICATES dropped)
    message(STATUS "drop_missing_includes: removed non-existent include directories of imported targets: ${dropped}")
  endif()
endfunction()

cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}" CALL _rimd_drop_missing_includes)
