# SPDX-License-Identifier: BSD-3-Clause
# Debian splits OpenCV into per-module -dev packages; only the metapackage libopencv-dev ships
# OpenCVConfig.cmake, and it pulls in ~45 packages (video I/O, GUI, contrib) that imucal never
# uses. This finds the few modules we need directly and defines imported targets with the
# same names OpenCVConfig would (opencv_core, ...).
find_path(IMUCAL_OPENCV_INCLUDE_DIR opencv2/core.hpp PATH_SUFFIXES opencv4 REQUIRED)
foreach(module core imgproc imgcodecs calib3d features2d flann)
  find_library(IMUCAL_OPENCV_${module}_LIBRARY opencv_${module})
  if(IMUCAL_OPENCV_${module}_LIBRARY AND NOT TARGET opencv_${module})
    add_library(opencv_${module} SHARED IMPORTED)
    set_target_properties(opencv_${module} PROPERTIES
      IMPORTED_LOCATION ${IMUCAL_OPENCV_${module}_LIBRARY}
      INTERFACE_INCLUDE_DIRECTORIES ${IMUCAL_OPENCV_INCLUDE_DIR})
  endif()
endforeach()
foreach(module core imgproc imgcodecs calib3d)
  if(NOT TARGET opencv_${module})
    message(FATAL_ERROR "OpenCV module ${module} not found: install libopencv-${module}-dev "
                        "(scripts/install-deps.sh does)")
  endif()
endforeach()
