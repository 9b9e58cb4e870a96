// Eigen's QR and SVD, for equilibrium.h and projection_qp.h only (see eigen.h for where
// Eigen comes from; ArduinoEigen's header already brings them).
#pragma once

#include "graspguide/eigen.h"

#if !(defined(ARDUINO) && __has_include(<ArduinoEigenDense.h>))
#include <Eigen/QR>
#include <Eigen/SVD>
#endif
