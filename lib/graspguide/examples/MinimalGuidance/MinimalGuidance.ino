// MinimalGuidance: the GraspGuide core on its own, no host. A three-finger grasp holds a
// virtual object whose weight points along -y of the hand; the sketch sweeps the hand's
// roll from 0 to 90 degrees and back, and drives the thimble motors (and prints) the PWM
// that tells the wearer which way to turn. Replace the sweep with your IMU's orientation
// (a w, x, y, z quaternion, hand to world, z up) to make a host-less guide.
#include <graspguide.h>

const uint8_t kMotorPins[3] = {13, 12, 27};  // thumb, index, middle: any PWM pins

graspguide::Guidance<float> guide;

void setup() {
  Serial.begin(115200);
  for (uint8_t pin : kMotorPins) {
    pinMode(pin, OUTPUT);
    analogWrite(pin, 0);
  }
  graspguide::Scene<float> scene;  // the paper's defaults: policy F, mode C, 3 deg, 0.5 s
  scene.k = 3;
  scene.contacts.col(0) << 0.045f, 0.045f, 0.035f;   // thumb tip, metres, hand frame
  scene.contacts.col(1) << 0.015f, 0.095f, 0.040f;   // index tip
  scene.contacts.col(2) << -0.010f, 0.100f, 0.040f;  // middle tip
  graspguide::Status s = guide.set_scene(scene);
  if (s == graspguide::Status::kOk) {
    graspguide::Vec6<float> weight;
    weight << 0.0f, -2.0f, 0.0f, 0.0f, 0.0f, 0.0f;  // N, N m in the object frame
    s = guide.set_wrench(weight);
  }
  if (s != graspguide::Status::kOk) {
    Serial.println(graspguide::status_message(s));
    while (true) delay(1000);  // motors stay off: fix the scene above
  }
}

void loop() {
  const float roll_rad = 0.785f * (1.0f - cosf(millis() * 0.0005f));  // 0..90 deg sweep
  Eigen::Vector4f q(cosf(roll_rad / 2), sinf(roll_rad / 2), 0.0f, 0.0f);
  graspguide::FrameResult<float> out;
  const graspguide::Status s = guide.update(q, out);  // on any error out.pwm is all zero
  for (int i = 0; i < 3; ++i) analogWrite(kMotorPins[i], out.pwm.duty[i]);
  Serial.print(graspguide::status_message(s));
  Serial.print(" error_deg=");
  Serial.print(out.error_deg);
  for (int i = 0; i < 3; ++i) {
    Serial.print(' ');
    Serial.print(out.pwm.duty[i]);
  }
  Serial.println();
  delay(20);
}
