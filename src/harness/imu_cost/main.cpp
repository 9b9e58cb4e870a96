// Instructions per gravity-estimator update on a Cortex-M4F (QEMU mps2-an386, -icount
// shift=0; see ../stage_counts/systick_counter.h). A hand turning at 90 deg/s about a
// tilted axis, sampled at 100 Hz with a constant gyro bias and a linear acceleration, is
// generated on the target and fed to GravityEstimator<float>::update one sample at a time;
// each update is timed alone (median and maximum, to one 40-instruction tick) and the
// whole stream together (the mean, to the instruction). tools/scripts/imu_cost.py runs it.
#include <math.h>

#include <cstdint>

#include "../stage_counts/line_buffer.h"
#include "../stage_counts/qemu_halt.h"
#include "../stage_counts/semihosting.h"
#include "../stage_counts/systick_counter.h"
#include "graspguide_cue/gravity_estimator.h"

namespace {

namespace gg = graspguide;
using stages::elapsed;
using stages::ticks;

constexpr int kSamples = 2000;
constexpr float kRateHz = 100.0f;
constexpr float kTurnRadps = 1.5707963f;  // 90 deg/s, the virtual participant's fastest
constexpr float kGravityMps2 = 9.80665f;

// The accelerometer and gyroscope of a hand turning about a fixed axis in its own frame:
// gravity, seen from the hand, turns the other way. The linear acceleration is a slow
// swing of the arm, the bias a constant gyro offset.
struct Stream {
  float g_hand[3] = {0.0f, 0.0f, -1.0f};
  float axis[3] = {0.48f, 0.6f, 0.64f};  // unit
  void sample(int n, float accel[3], float gyro[3]) {
    const float dt = 1.0f / kRateHz;
    // g' = -w x g: rotate the hand-frame gravity by the turn of this step.
    const float w[3] = {kTurnRadps * axis[0], kTurnRadps * axis[1], kTurnRadps * axis[2]};
    const float c[3] = {w[1] * g_hand[2] - w[2] * g_hand[1], w[2] * g_hand[0] - w[0] * g_hand[2],
                        w[0] * g_hand[1] - w[1] * g_hand[0]};
    float norm = 0.0f;
    for (int i = 0; i < 3; ++i) {
      g_hand[i] -= c[i] * dt;
      norm += g_hand[i] * g_hand[i];
    }
    norm = sqrtf(norm);
    const float swing = 0.5f * sinf(6.2831853f * 0.7f * n * dt);
    for (int i = 0; i < 3; ++i) {
      g_hand[i] /= norm;
      accel[i] = -kGravityMps2 * g_hand[i] + (i == 0 ? swing : 0.0f);
      gyro[i] = w[i] + (i == 1 ? 0.014f : -0.01f);  // about 0.6-0.8 deg/s of bias
    }
  }
};

volatile float g_sink;

void sort(int32_t* v, int n) {
  for (int i = 1; i < n; ++i)
    for (int j = i; j > 0 && v[j - 1] > v[j]; --j) {
      const int32_t t = v[j];
      v[j] = v[j - 1];
      v[j - 1] = t;
    }
}

int32_t g_each[kSamples];
float g_accel[kSamples][3], g_gyro[kSamples][3];

}  // namespace

int main() {
  stages::start_counter();
  stages::LineBuffer line;
  uint32_t t0 = ticks();
  const int32_t empty = elapsed(t0, ticks());
  t0 = ticks();
  stages::known_loop(100000);
  const int32_t loop_a = elapsed(t0, ticks());
  t0 = ticks();
  stages::known_loop(300000);
  const int32_t loop_b = elapsed(t0, ticks());
  stages::write0(line.str("CAL ").num(empty).sp().num(loop_a).sp().num(loop_b).end());

  Stream stream;
  for (int n = 0; n < kSamples; ++n) stream.sample(n, g_accel[n], g_gyro[n]);
  const float dt = 1.0f / kRateHz;

  gg::GravityEstimator<float> each;
  int failed = 0;
  for (int n = 0; n < kSamples; ++n) {
    t0 = ticks();
    const gg::Status s = each.update(g_accel[n], g_gyro[n], dt);
    g_each[n] = elapsed(t0, ticks());
    failed += s != gg::Status::kOk;
  }
  g_sink = each.gravity()[2];

  gg::GravityEstimator<float> whole;
  t0 = ticks();
  for (int n = 0; n < kSamples; ++n) whole.update(g_accel[n], g_gyro[n], dt);
  const int32_t total = elapsed(t0, ticks());
  g_sink = whole.gravity()[2];

  // The estimate against the stream's own gravity at the end: a check that the timed
  // code did its job, not only that it ran.
  float dot = 0.0f;
  for (int i = 0; i < 3; ++i) dot += whole.gravity()[i] * stream.g_hand[i];
  const int32_t error_mdeg = int32_t(acosf(dot > 1.0f ? 1.0f : dot) * 57295.78f);

  sort(g_each, kSamples);
  stages::write0(line.str("IMU samples ").num(kSamples).str(" failed ").num(failed).end());
  stages::write0(line.str("EACH median ")
                     .num(g_each[kSamples / 2])
                     .str(" max ")
                     .num(g_each[kSamples - 1])
                     .end());
  stages::write0(line.str("TOTAL ").num(total).end());
  stages::write0(line.str("ERROR_MDEG ").num(error_mdeg).end());
  stages::write0(line.str("STACK ").num(m4f_stack_high_water()).end());
  stages::exit(0);
}
