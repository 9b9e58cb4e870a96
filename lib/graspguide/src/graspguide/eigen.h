// Where Eigen comes from. Host, simulated-device and bare-metal builds use Debian's Eigen
// 3.4 (-I/usr/include/eigen3). Arduino builds use the ArduinoEigen library, whose copy of
// Eigen sits under ArduinoEigen/ and is only reachable through its own header, so
// <Eigen/...> would not be found there. Here: the dense core and geometry; the
// decompositions come from eigen_decompositions.h, included only where they are used.
#pragma once

#if defined(ARDUINO) && __has_include(<ArduinoEigenDense.h>)
#include <ArduinoEigenDense.h>
#else
#include <Eigen/Core>
#include <Eigen/Geometry>
#endif
