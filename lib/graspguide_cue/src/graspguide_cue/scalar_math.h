// The few libm calls the per-frame layer makes, for float and double, from <math.h> only:
// avr-libc has no <cmath>, and on an AVR double is float, so both overloads exist there too.
#pragma once

#include <float.h>
#include <math.h>

namespace graspguide {
namespace scalar_math {

inline float sqrt_of(float x) { return sqrtf(x); }
inline double sqrt_of(double x) { return sqrt(x); }
// (180 / pi) asin(x) / x for z = x^2 in [0, 0.25]: the error angle's one transcendental
// function, in a form that takes the scalings of alignment.h with it. In float a cubic in z,
// fitted by weighted least squares on Chebyshev nodes for the relative error of asin over
// |x| <= 0.5: largest relative error 1.7e-7, about one unit in the last place (libm's asinf:
// 7.1e-8), checked by test/test_cue. avr-libc's asinf covers [-1, 1] and costs 2,614
// cycles on the ATmega328P; this costs about 1,200.
inline float asin_deg_ratio(float z) {
  return (((2.89023395f * z + 2.27760342f) * z + 4.32354196f) * z + 9.54844901f) * z + 57.2957838f;
}
inline double asin_deg_ratio(double z) {
  constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;
  if (!(z > 0)) return kRadToDeg;
  const double x = sqrt(z);
  return asin(x) / x * kRadToDeg;
}
inline float floor_of(float x) { return floorf(x); }
inline double floor_of(double x) { return floor(x); }

template <typename T>
inline T abs_of(T x) {
  return x < T(0) ? -x : x;
}

template <typename T>
struct Limits;
template <>
struct Limits<float> {
  static constexpr float kMax = FLT_MAX;
};
template <>
struct Limits<double> {
  static constexpr double kMax = DBL_MAX;
};

// NaN fails both comparisons and infinity the second.
template <typename T>
inline bool is_finite(T x) {
  return abs_of(x) <= Limits<T>::kMax;
}

}  // namespace scalar_math
}  // namespace graspguide
