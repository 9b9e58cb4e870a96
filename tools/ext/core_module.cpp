// graspguide.core._core: the GraspGuide C++ core (lib/graspguide) for Python, via nanobind.
//
// Only graspguide::Guidance<float> and Guidance<double> are instantiated here; the heavy
// templates (QR, SVD, QP, steps 1-6) are `extern template` in the core's headers and
// compiled once in lib/graspguide/src/*.cpp, which CMake links into this module.
//
// Python types are converted by nanobind (a wrong type or length raises TypeError); the
// names of policies, modes, models, scalars and decompositions raise ValueError listing
// the accepted ones. Every number, NaN and infinities included, is handed to the core,
// which answers with a Status: nothing here reads a value to decide anything else.
#include <nanobind/nanobind.h>
#include <nanobind/stl/array.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/vector.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "graspguide.h"
#include "graspguide_cue/gravity_estimator.h"

namespace nb = nanobind;
using namespace nb::literals;
namespace gg = graspguide;

namespace {

using ContactList = std::vector<std::array<double, 3>>;
using Wrench = std::array<double, 6>;
using Quat4 = std::array<double, 4>;
using Axis3 = std::array<double, 3>;

// The statuses are contiguous from kOk to the last one (status.h keeps kStatusCount).
inline gg::Status status_at(int i) { return static_cast<gg::Status>(i); }

constexpr const char* decomposition_name(gg::Decomposition d) {
  return d == gg::Decomposition::kStructured ? "structured" : "svd";
}

// A name for an error message: printable ASCII, at most 40 characters (the message
// goes through a C string, so an embedded NUL would cut it).
std::string shown(const std::string& s) {
  static const char* hex = "0123456789abcdef";
  std::string out;
  for (unsigned char c : s) {
    if (out.size() >= 40) {
      out += "...";
      break;
    }
    if (c >= 0x20 && c < 0x7f && c != '\\') {
      out += static_cast<char>(c);
    } else {
      out += "\\x";
      out += hex[c >> 4];
      out += hex[c & 15];
    }
  }
  return out;
}

// Exact, case-sensitive name lookup (std::string comparison, so an embedded NUL never
// matches a shorter name).
template <typename E, std::size_t N>
E parse_name(const std::string& s, const E (&values)[N], const char* (*name)(E), const char* what) {
  for (E v : values)
    if (s == name(v)) return v;
  std::string accepted;
  for (std::size_t i = 0; i < N; ++i) {
    accepted += i ? ", '" : "'";
    accepted += name(values[i]);
    accepted += "'";
  }
  throw nb::value_error(
      (std::string("unknown ") + what + " '" + shown(s) + "'; accepted: " + accepted).c_str());
}

constexpr gg::Policy kPolicies[] = {gg::Policy::kF, gg::Policy::kFperp};
constexpr gg::Mode kModes[] = {gg::Mode::kC, gg::Mode::kV};
constexpr gg::ConstraintModel kModels[] = {
    gg::ConstraintModel::kPaper, gg::ConstraintModel::kNormal, gg::ConstraintModel::kNone};
constexpr gg::Decomposition kDecompositions[] = {gg::Decomposition::kStructured,
                                                 gg::Decomposition::kSVD};

const char* policy_name_fn(gg::Policy p) { return gg::policy_name(p); }
const char* mode_name_fn(gg::Mode m) { return gg::mode_name(m); }
const char* model_name_fn(gg::ConstraintModel m) { return gg::constraint_model_name(m); }
const char* decomposition_name_fn(gg::Decomposition d) { return decomposition_name(d); }

struct SceneOptions {
  gg::Policy policy = gg::Policy::kF;
  gg::Mode mode = gg::Mode::kC;
  gg::ConstraintModel constraints = gg::ConstraintModel::kPaper;
  gg::Decomposition decomposition = gg::Decomposition::kStructured;
  int max_iterations = gg::kDefaultMaxIterations;
};

SceneOptions parse_options(const std::string& policy, const std::string& mode,
                           const std::string& constraints, const std::string& decomposition,
                           int max_iterations) {
  SceneOptions o;
  o.policy = parse_name(policy, kPolicies, policy_name_fn, "policy");
  o.mode = parse_name(mode, kModes, mode_name_fn, "mode");
  o.constraints = parse_name(constraints, kModels, model_name_fn, "constraint model");
  o.decomposition =
      parse_name(decomposition, kDecompositions, decomposition_name_fn, "decomposition");
  o.max_iterations = max_iterations;  // < 1 is the core's bad_config
  return o;
}

// The contact count is passed on as given (capped, so it fits an int): the core answers
// bad_contact_count for anything but 3 or 4. Only the first kMaxContacts are copied.
int contact_count(const ContactList& contacts) {
  return static_cast<int>(std::min<std::size_t>(contacts.size(), 1u << 20));
}

template <typename T>
void fill_contacts(const ContactList& contacts, Eigen::Matrix<T, 3, gg::kMaxContacts>& out) {
  out.setZero();
  const int n = std::min<int>(contact_count(contacts), gg::kMaxContacts);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < 3; ++j) out(j, i) = static_cast<T>(contacts[i][j]);
}

template <typename T>
gg::Scene<T> make_scene(const ContactList& contacts, const Axis3& y_axis, const SceneOptions& o) {
  gg::Scene<T> s;
  s.k = contact_count(contacts);
  fill_contacts<T>(contacts, s.contacts);
  s.y_axis =
      gg::Vec3<T>(static_cast<T>(y_axis[0]), static_cast<T>(y_axis[1]), static_cast<T>(y_axis[2]));
  s.constraints = o.constraints;
  s.policy = o.policy;
  s.mode = o.mode;
  s.solver.decomposition = o.decomposition;
  s.solver.max_iterations = o.max_iterations;
  return s;
}

template <typename T>
gg::Vec6<T> make_wrench(const Wrench& w) {
  gg::Vec6<T> v;
  for (int i = 0; i < 6; ++i) v(i) = static_cast<T>(w[i]);
  return v;
}

template <typename T>
Eigen::Matrix<T, 4, 1> make_quat(const Quat4& q) {
  return Eigen::Matrix<T, 4, 1>(static_cast<T>(q[0]), static_cast<T>(q[1]), static_cast<T>(q[2]),
                                static_cast<T>(q[3]));
}

// The result of one frame as a dict. Outputs that the status leaves undefined are None
// (levels, lambda, relevant, error_deg, alpha) or "" (constraints_used); pwm is always k
// ints, all 0 unless the status is ok. iterations and rank_ratio describe the last grasp
// computation (0 if it did not get that far).
template <typename T>
nb::dict result_dict(gg::Status status, int k, const gg::FrameResult<T>& fr,
                     const gg::GraspSolution<T>& g) {
  const bool ok = status == gg::Status::kOk;
  nb::dict d;
  d["status"] = gg::status_name(status);
  nb::list pwm;
  for (int i = 0; i < k; ++i) pwm.append(ok && i < gg::kMaxContacts ? int(fr.pwm.duty[i]) : 0);
  d["pwm"] = pwm;
  if (ok) {
    nb::list levels, lambda, relevant;
    for (int i = 0; i < k; ++i) {
      levels.append(double(g.levels(i)));
      relevant.append(bool(g.relevant_mask & (1u << i)));
      for (int j = 0; j < 3; ++j) lambda.append(double(g.lambda(3 * i + j)));
    }
    d["levels"] = levels;
    d["lambda"] = lambda;
    d["constraints_used"] = gg::constraint_model_name(g.used);
    d["relevant"] = relevant;
    d["error_deg"] = double(fr.error_deg);
    d["alpha"] = double(fr.alpha);
    d["fallback_mask"] = int(g.fallback_mask);
  } else {
    d["levels"] = nb::none();
    d["lambda"] = nb::none();
    d["constraints_used"] = "";
    d["relevant"] = nb::none();
    d["error_deg"] = nb::none();
    d["alpha"] = nb::none();
    d["fallback_mask"] = 0;
  }
  d["iterations"] = g.iterations;
  d["rank_ratio"] = double(g.rank_ratio);
  d["retried"] = g.retried;
  d["recomputed"] = fr.recomputed;
  return d;
}

// One-shot Algorithm 1 through Guidance<T>::solve, which checks in one order whatever is
// wrong: non-finite input, contact count, axis, quaternion, then the geometry.
template <typename T>
nb::dict solve_t(const ContactList& contacts, const Wrench& wrench, const SceneOptions& o,
                 const Quat4& orientation, const Axis3& y_axis) {
  gg::Guidance<T> guidance;
  gg::FrameResult<T> fr;
  const gg::Status s = guidance.solve(make_scene<T>(contacts, y_axis, o), make_wrench<T>(wrench),
                                      make_quat<T>(orientation), fr);
  return result_dict<T>(s, contact_count(contacts), fr, guidance.grasp());
}

// "float" or "double" (the scalar every binding takes); anything else is a ValueError.
bool is_float_scalar(const std::string& scalar) {
  if (scalar == "float") return true;
  if (scalar == "double") return false;
  throw nb::value_error(
      ("unknown scalar '" + shown(scalar) + "'; accepted: 'double', 'float'").c_str());
}

nb::dict solve(const ContactList& contacts, const Wrench& wrench, const std::string& policy,
               const std::string& mode, const std::string& constraints, const Quat4& orientation,
               const Axis3& y_axis, const std::string& scalar, const std::string& decomposition,
               int max_iterations) {
  const SceneOptions o = parse_options(policy, mode, constraints, decomposition, max_iterations);
  return is_float_scalar(scalar) ? solve_t<float>(contacts, wrench, o, orientation, y_axis)
                                 : solve_t<double>(contacts, wrench, o, orientation, y_axis);
}

// The fast path of the public solve() (graspguide.core.solver): its arguments read only
// when each has exactly a plain type (a list or tuple of float and int, a str name, an int
// cap). Anything else, a subclass included (bool is one of int), is "not plain": the
// function returns None and the Python wrapper runs its thorough checks, so those stay
// the only source of error messages. A plain request gets the same dict as solve().
namespace plain {

// Rows beyond this are never read by the core; the wrapper forwards at most as many.
constexpr Py_ssize_t kMaxForwardedContacts = 64;

bool number(PyObject* o, double& out) {
  if (PyFloat_CheckExact(o)) {
    out = PyFloat_AS_DOUBLE(o);
    return true;
  }
  if (!PyLong_CheckExact(o)) return false;
  out = PyLong_AsDouble(o);  // what float(int) computes
  if (out == -1.0 && PyErr_Occurred()) {
    PyErr_Clear();  // beyond the double range: the wrapper makes it infinite
    return false;
  }
  return true;
}

bool sequence(PyObject* o, Py_ssize_t n) {
  return (PyList_CheckExact(o) || PyTuple_CheckExact(o)) && PySequence_Fast_GET_SIZE(o) == n;
}

template <std::size_t N>
bool numbers(nb::handle h, std::array<double, N>& out) {
  PyObject* o = h.ptr();
  if (!sequence(o, Py_ssize_t(N))) return false;
  PyObject** items = PySequence_Fast_ITEMS(o);
  for (std::size_t i = 0; i < N; ++i)
    if (!number(items[i], out[i])) return false;
  return true;
}

bool contacts(nb::handle h, ContactList& out) {
  PyObject* o = h.ptr();
  if (!PyList_CheckExact(o) && !PyTuple_CheckExact(o)) return false;
  const Py_ssize_t n = PySequence_Fast_GET_SIZE(o);
  if (n > kMaxForwardedContacts) return false;
  out.resize(static_cast<std::size_t>(n));
  PyObject** rows = PySequence_Fast_ITEMS(o);
  for (Py_ssize_t i = 0; i < n; ++i)
    if (!numbers<3>(rows[i], out[static_cast<std::size_t>(i)])) return false;
  return true;
}

// The index of an exact str among the names, or -1.
template <typename E, std::size_t N>
int name_index(nb::handle h, const E (&values)[N], const char* (*name)(E)) {
  PyObject* o = h.ptr();
  if (!PyUnicode_CheckExact(o)) return -1;
  Py_ssize_t size = 0;
  const char* text = PyUnicode_AsUTF8AndSize(o, &size);
  if (text == nullptr) {
    PyErr_Clear();  // not encodable (a lone surrogate): no name matches it
    return -1;
  }
  for (std::size_t i = 0; i < N; ++i)
    if (std::string_view(text, static_cast<std::size_t>(size)) == name(values[i])) return int(i);
  return -1;
}

bool max_iterations(nb::handle h, int& out) {
  PyObject* o = h.ptr();
  if (!PyLong_CheckExact(o)) return false;
  int overflow = 0;
  const long long v = PyLong_AsLongLongAndOverflow(o, &overflow);
  if (v == -1 && PyErr_Occurred()) {
    PyErr_Clear();
    return false;
  }
  // As the wrapper clamps: below 1 is the core's bad_config, the binding takes a C int.
  constexpr long long kMax = std::numeric_limits<int>::max();
  out = overflow > 0 ? int(kMax) : overflow < 0 ? -1 : int(std::max(-1LL, std::min(v, kMax)));
  return true;
}

const char* scalar_name(bool is_float) { return is_float ? "float" : "double"; }

}  // namespace plain

template <std::size_t N>
nb::list float_list(const std::array<double, N>& v) {
  nb::list out;
  for (double x : v) out.append(x);
  return out;
}

// The numbers of a request read as solve_plain reads them, as new lists of floats:
// (contacts, wrench, orientation, y_axis), or None when any is not plain.
nb::object plain_numbers(nb::handle contacts, nb::handle wrench, nb::handle orientation,
                         nb::handle y_axis) {
  ContactList c;
  Wrench w;
  Quat4 q;
  Axis3 y;
  if (!plain::contacts(contacts, c) || !plain::numbers(wrench, w) ||
      !plain::numbers(orientation, q) || !plain::numbers(y_axis, y))
    return nb::none();
  nb::list rows;
  for (const auto& row : c) rows.append(float_list(row));
  return nb::make_tuple(rows, float_list(w), float_list(q), float_list(y));
}

nb::object solve_plain(nb::handle contacts, nb::handle wrench, nb::handle policy, nb::handle mode,
                       nb::handle constraints, nb::handle orientation, nb::handle y_axis,
                       nb::handle scalar, nb::handle decomposition, nb::handle max_iterations) {
  ContactList c;
  Wrench w;
  Quat4 q;
  Axis3 y;
  SceneOptions o;
  constexpr bool kScalars[] = {false, true};
  const int ip = plain::name_index(policy, kPolicies, policy_name_fn);
  const int im = plain::name_index(mode, kModes, mode_name_fn);
  const int ic = plain::name_index(constraints, kModels, model_name_fn);
  const int id = plain::name_index(decomposition, kDecompositions, decomposition_name_fn);
  const int is = plain::name_index(scalar, kScalars, plain::scalar_name);
  if (ip < 0 || im < 0 || ic < 0 || id < 0 || is < 0 ||
      !plain::max_iterations(max_iterations, o.max_iterations) || !plain::contacts(contacts, c) ||
      !plain::numbers(wrench, w) || !plain::numbers(orientation, q) || !plain::numbers(y_axis, y))
    return nb::none();
  o.policy = kPolicies[ip];
  o.mode = kModes[im];
  o.constraints = kModels[ic];
  o.decomposition = kDecompositions[id];
  return kScalars[is] ? solve_t<float>(c, w, o, q, y) : solve_t<double>(c, w, o, q, y);
}

// Stateful guidance in double, as the firmware runs it frame by frame.
class PyGuidance {
 public:
  PyGuidance() : g_(std::make_unique<gg::Guidance<double>>()) {}

  std::string set_scene(const ContactList& contacts, const std::string& policy,
                        const std::string& mode, const std::string& constraints,
                        const Axis3& y_axis, const std::string& decomposition, int max_iterations) {
    const SceneOptions o = parse_options(policy, mode, constraints, decomposition, max_iterations);
    return gg::status_name(g_->set_scene(make_scene<double>(contacts, y_axis, o)));
  }

  std::string set_wrench(const Wrench& wrench) {
    return gg::status_name(g_->set_wrench(make_wrench<double>(wrench)));
  }

  // The count must stay the scene's k (change it with set_scene).
  std::string set_contacts(const ContactList& contacts) {
    if (contact_count(contacts) != g_->scene().k)
      return gg::status_name(gg::Status::kBadContactCount);
    Eigen::Matrix<double, 3, gg::kMaxContacts> c;
    fill_contacts<double>(contacts, c);
    return gg::status_name(g_->set_contacts(c));
  }

  nb::dict update(const Quat4& orientation) {
    gg::FrameResult<double> fr;
    const gg::Status s = g_->update(make_quat<double>(orientation), fr);
    return result_dict<double>(s, g_->scene().k, fr, g_->grasp());
  }

  int k() const { return g_->scene().k; }

 private:
  std::unique_ptr<gg::Guidance<double>> g_;  // heap: Eigen members need 16-byte alignment
};

// The device's gravity estimator (graspguide_cue/gravity_estimator.h) in float (as the
// MCU runs it) or double, so Python can run the same C++ on an IMU stream.
template <typename T>
struct GravityState {
  gg::GravityEstimator<T> est;

  std::string configure(double kp, double ki, double gate) {
    gg::GravityGains<T> g;
    g.kp_per_s = T(kp);
    g.ki_per_s2 = T(ki);
    g.accel_gate_mps2 = T(gate);
    return gg::status_name(est.configure(g));
  }
  std::string update(const Axis3& a, const Axis3& w, double dt) {
    const T at[3] = {T(a[0]), T(a[1]), T(a[2])}, wt[3] = {T(w[0]), T(w[1]), T(w[2])};
    return gg::status_name(est.update(at, wt, T(dt)));
  }
  std::string set_fused(const Axis3& v) {
    const T vt[3] = {T(v[0]), T(v[1]), T(v[2])};
    return gg::status_name(est.set_fused(vt));
  }
  static Axis3 out(const T* v) { return {double(v[0]), double(v[1]), double(v[2])}; }
};

class PyGravityEstimator {
 public:
  explicit PyGravityEstimator(const std::string& scalar) : is_float_(is_float_scalar(scalar)) {}

  std::string configure(double kp, double ki, double gate) {
    return is_float_ ? f_.configure(kp, ki, gate) : d_.configure(kp, ki, gate);
  }
  std::string update(const Axis3& accel, const Axis3& gyro, double dt) {
    return is_float_ ? f_.update(accel, gyro, dt) : d_.update(accel, gyro, dt);
  }
  // A whole stream in one call: the gravity estimate after each sample, or the first
  // refused sample's index and status as a ValueError (earlier samples stay applied).
  std::vector<Axis3> run(const std::vector<Axis3>& accel, const std::vector<Axis3>& gyro,
                         double dt) {
    if (accel.size() != gyro.size())
      throw nb::value_error(("accel and gyro must have the same length, got " +
                             std::to_string(accel.size()) + " and " + std::to_string(gyro.size()))
                                .c_str());
    std::vector<Axis3> out;
    out.reserve(accel.size());
    for (std::size_t i = 0; i < accel.size(); ++i) {
      const std::string s = update(accel[i], gyro[i], dt);
      if (s != "ok")
        throw nb::value_error(("sample " + std::to_string(i) + " refused: " + s).c_str());
      out.push_back(gravity());
    }
    return out;
  }
  std::string set_fused(const Axis3& v) { return is_float_ ? f_.set_fused(v) : d_.set_fused(v); }
  void reset() { is_float_ ? f_.est.reset() : d_.est.reset(); }
  Axis3 gravity() const { return is_float_ ? f_.out(f_.est.gravity()) : d_.out(d_.est.gravity()); }
  Axis3 bias() const {
    return is_float_ ? f_.out(f_.est.bias_radps()) : d_.out(d_.est.bias_radps());
  }
  bool initialised() const { return is_float_ ? f_.est.initialised() : d_.est.initialised(); }
  bool accel_trusted() const { return is_float_ ? f_.est.accel_trusted() : d_.est.accel_trusted(); }

 private:
  bool is_float_;
  GravityState<float> f_;
  GravityState<double> d_;
};

nb::dict tolerances(bool is_float) {
  nb::dict d;
  d["kCoincidentRelTol"] = gg::kCoincidentRelTol;
  d["kAxisParallelTol"] = gg::kAxisParallelTol;
  d["kRankRelTol"] = gg::kRankRelTol;
  d["kZeroForceRelTol"] = gg::kZeroForceRelTol;
  d["kRelevanceCosTol"] = gg::kRelevanceCosTol;
  d["kTinyRel"] = gg::kTinyRel;
  d["kFeasRelTol"] =
      is_float ? double(gg::Tolerances<float>::kFeasRelTol) : gg::Tolerances<double>::kFeasRelTol;
  d["kDependentRelTol"] = is_float ? double(gg::Tolerances<float>::kDependentRelTol)
                                   : gg::Tolerances<double>::kDependentRelTol;
  d["kMotorOffLevel"] = gg::kMotorOffLevel;
  d["kMinQuaternionNorm"] = gg::kMinQuaternionNorm;
  return d;
}

constexpr const char* kResultDoc =
    "dict with keys: status (str, 'ok' or an error name from STATUS_NAMES), pwm (k ints, "
    "all 0 unless ok), levels (k floats: normalised motor levels m, signed for Fperp), "
    "lambda (3k floats: contact forces [x y z] per contact before normalisation), "
    "constraints_used ('paper'/'normal'/'none', '' unless ok), relevant (k bools), "
    "error_deg, alpha (floats), fallback_mask (int), iterations (int: QP active-set "
    "changes), rank_ratio (float), retried (bool: a float solve that could not vouch for "
    "its answer ran again in double), recomputed (bool: the grasp part ran). levels, lambda, "
    "relevant, error_deg and alpha are None unless status is 'ok'.";

// ---------------------------------------------------------------------------------------
// Timing entries for `graspguide bench` (tools/graspguide/bench/host_bench.py). The loops run here,
// in C++, so that Python's per-call overhead (~1 us, larger than a whole frame) is not
// in the figures. Every sample is the mean of `reps` consecutive calls on one instance,
// timed with steady_clock around the whole batch (one clock read per batch, not per call,
// so the clock's own ~20 ns stay out of the per-call figure).
// ---------------------------------------------------------------------------------------

// Written after every batch so the optimiser cannot drop the work it depends on.
volatile std::uint32_t g_bench_sink = 0;

template <typename F>
std::vector<double> time_batches(F&& call, int reps, int batches, int warmup) {
  for (int i = 0; i < warmup; ++i) g_bench_sink = g_bench_sink + call(i);
  std::vector<double> out;
  out.reserve(static_cast<std::size_t>(batches));
  for (int b = 0; b < batches; ++b) {
    std::uint32_t acc = 0;
    const auto t0 = std::chrono::steady_clock::now();
    for (int r = 0; r < reps; ++r) acc += call(r);
    const auto t1 = std::chrono::steady_clock::now();
    g_bench_sink = g_bench_sink + acc;
    out.push_back(double(std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - t0).count()) /
                  reps);
  }
  return out;
}

void check_timing_args(int reps, int batches, int warmup) {
  if (reps < 1 || batches < 1 || warmup < 0)
    throw nb::value_error("reps and batches must be >= 1 and warmup >= 0");
}

template <typename V>
void check_count(const V& v, std::size_t n, const char* what) {
  if (v.size() != n)
    throw nb::value_error((std::string(what) + " has " + std::to_string(v.size()) +
                           " entries; expected one per instance (" + std::to_string(n) + ")")
                              .c_str());
}

// What every timing loop returns: the samples and, per instance, the answer it timed.
nb::dict timing_result(const nb::list& ns, const nb::list& status, const nb::list& lambda,
                       const nb::list& used, const nb::list& iterations) {
  nb::dict d;
  d["ns"] = ns;
  d["status"] = status;
  d["lambda"] = lambda;
  d["constraints_used"] = used;
  d["iterations"] = iterations;
  return d;
}

// graspguide bench's instances, one entry per instance in every list: contacts, wrenches,
// orientations, y axes, policies, modes and constraint models. One tuple, so that every
// timing function takes (and checks) them the same way.
using InstanceLists = std::tuple<std::vector<ContactList>, std::vector<Wrench>, std::vector<Quat4>,
                                 std::vector<Axis3>, std::vector<std::string>,
                                 std::vector<std::string>, std::vector<std::string>>;

// The options of each instance of time_frames / time_stages, once every per-instance list
// is checked to have one entry per instance.
std::vector<SceneOptions> instance_options(const InstanceLists& instances,
                                           const std::string& decomposition, int max_iterations) {
  const auto& [contacts, wrenches, orientations, y_axes, policies, modes, constraints] = instances;
  const std::size_t n = contacts.size();
  check_count(wrenches, n, "wrenches");
  check_count(orientations, n, "orientations");
  check_count(y_axes, n, "y_axes");
  check_count(policies, n, "policies");
  check_count(modes, n, "modes");
  check_count(constraints, n, "constraints");
  std::vector<SceneOptions> options;
  for (std::size_t i = 0; i < n; ++i)
    options.push_back(
        parse_options(policies[i], modes[i], constraints[i], decomposition, max_iterations));
  return options;
}

// The contacts moved by one unit in the last place: enough for Guidance to see new
// contacts and run the grasp part again (it compares them exactly), too little to change
// the answer. This is the tracking case: a new posture every frame, close to the last.
template <typename T>
Eigen::Matrix<T, 3, gg::kMaxContacts> nudged(const Eigen::Matrix<T, 3, gg::kMaxContacts>& c) {
  Eigen::Matrix<T, 3, gg::kMaxContacts> out = c;
  for (int i = 0; i < out.size(); ++i)
    out.data()[i] = std::nextafter(out.data()[i], std::numeric_limits<T>::infinity());
  return out;
}

template <typename T>
void frame_outputs(gg::Status s, int k, const gg::FrameResult<T>& fr, const gg::GraspSolution<T>& g,
                   nb::list& status, nb::list& pwm, nb::list& lambda, nb::list& used,
                   nb::list& iterations) {
  const bool ok = s == gg::Status::kOk;
  status.append(gg::status_name(s));
  nb::list p, l;
  for (int i = 0; i < k && i < gg::kMaxContacts; ++i) {
    p.append(ok ? int(fr.pwm.duty[i]) : 0);
    for (int j = 0; j < 3; ++j) l.append(double(g.lambda(3 * i + j)));
  }
  pwm.append(p);
  lambda.append(ok ? nb::object(l) : nb::none());
  used.append(ok ? gg::constraint_model_name(g.used) : "");
  iterations.append(g.iterations);
}

// One Guidance<T> per instance. Moving posture: every frame sets new contacts (alternately
// the instance's own and their nudged copy) and runs update(), i.e. contact frames, grasp
// structure (or the SVD route's decomposition), QP, levels and PWM. Fixed posture: only the
// orientation changes, so a frame is the orientation error, alpha and the PWM mapping.
template <typename T>
nb::dict time_frames_t(const std::vector<ContactList>& contacts,
                       const std::vector<Wrench>& wrenches, const std::vector<Quat4>& orientations,
                       const std::vector<Axis3>& y_axes, const std::vector<SceneOptions>& options,
                       bool fixed_posture, int reps, int batches, int warmup) {
  nb::list ns, status, pwm, lambda, used, iterations, recomputed;
  auto g = std::make_unique<gg::Guidance<T>>();
  for (std::size_t n = 0; n < contacts.size(); ++n) {
    gg::Scene<T> scene = make_scene<T>(contacts[n], y_axes[n], options[n]);
    const int k = contact_count(contacts[n]);
    gg::FrameResult<T> fr;
    gg::Status s = g->set_scene(scene);
    if (s == gg::Status::kOk) s = g->set_wrench(make_wrench<T>(wrenches[n]));
    if (s != gg::Status::kOk) {  // nothing to time: reported as this instance's status
      ns.append(nb::list());
      frame_outputs<T>(s, k, fr, g->grasp(), status, pwm, lambda, used, iterations);
      recomputed.append(0);
      continue;
    }
    const auto base = scene.contacts;
    const auto moved = nudged<T>(base);
    const auto q0 = make_quat<T>(orientations[n]);
    // Four orientations of the same rotation (sign and scale): real work for
    // unit_quaternion and alignment, the same answer.
    const Eigen::Matrix<T, 4, 1> quats[4] = {q0, -q0, q0 * T(1.0009765625), -q0 * T(0.5)};
    int recomputations = 0;
    std::vector<double> samples;
    if (fixed_posture) {
      g->update(q0, fr);  // the grasp part once, outside the timing
      samples = time_batches(
          [&](int r) {
            g->update(quats[r & 3], fr);
            recomputations += fr.recomputed;
            return std::uint32_t(fr.pwm.duty[0]);
          },
          reps, batches, warmup);
    } else {
      samples = time_batches(
          [&](int r) {
            g->set_contacts((r & 1) ? moved : base);
            g->update(q0, fr);
            recomputations += fr.recomputed;
            return std::uint32_t(fr.pwm.duty[0]);
          },
          reps, batches, warmup);
      g->set_contacts(base);
    }
    s = g->update(q0, fr);
    nb::list sample_list;
    for (double v : samples) sample_list.append(v);
    ns.append(sample_list);
    frame_outputs<T>(s, k, fr, g->grasp(), status, pwm, lambda, used, iterations);
    recomputed.append(recomputations);
  }
  nb::dict d = timing_result(ns, status, lambda, used, iterations);
  d["pwm"] = pwm;
  d["recomputed"] = recomputed;
  d["frames_per_instance"] = (reps * batches) + warmup;
  return d;
}

nb::dict time_frames(const InstanceLists& instances, const std::string& scalar,
                     const std::string& decomposition, int max_iterations, bool fixed_posture,
                     int reps, int batches, int warmup) {
  const std::vector<SceneOptions> options =
      instance_options(instances, decomposition, max_iterations);
  const auto& [contacts, wrenches, orientations, y_axes, policies, modes, constraints] = instances;
  check_timing_args(reps, batches, warmup);
  if (is_float_scalar(scalar))
    return time_frames_t<float>(contacts, wrenches, orientations, y_axes, options, fixed_posture,
                                reps, batches, warmup);
  return time_frames_t<double>(contacts, wrenches, orientations, y_axes, options, fixed_posture,
                               reps, batches, warmup);
}

// The QP alone (step 5 with its fallback chain) on the data every solver of the bench is
// handed (float64 lambda0, null basis and lambda_des, computed by the reference): the
// null-space QP of the SVD reference route (projection_qp.h), DAQP's exact problem. The
// structured route's QP needs the grasp structure instead; time_stages times it.
template <typename T, int K>
void time_qp_k(const std::vector<double>& lambda0, const std::vector<double>& null_basis,
               const std::vector<double>& lambda_des, gg::ConstraintModel model, int max_iterations,
               double violation_rel, int reps, int batches, int warmup, nb::list& ns,
               nb::list& status, nb::list& lambda, nb::list& used, nb::list& iterations) {
  constexpr int kVars = 3 * K - 6;
  auto eq = std::make_unique<gg::Equilibrium<T, K>>();
  gg::ForceVec<T, K> des;
  for (int i = 0; i < 3 * K; ++i) {
    eq->lambda0(i) = static_cast<T>(lambda0[i]);
    des(i) = static_cast<T>(lambda_des[i]);
    for (int j = 0; j < kVars; ++j)
      eq->null_basis(i, j) = static_cast<T>(null_basis[std::size_t(i) * kVars + j]);
  }
  const T tol = violation_rel > 0 ? static_cast<T>(violation_rel) : gg::Tolerances<T>::kFeasRelTol;
  gg::ForceVec<T, K> out;
  gg::ConstraintModel model_used = gg::ConstraintModel::kNone;
  int its = 0;
  auto solve = [&]() {
    return gg::solve_forces_svd<T, K>(*eq, des, model, max_iterations, out, model_used, its, tol);
  };
  const std::vector<double> samples = time_batches(
      [&](int) {
        const gg::Status s = solve();
        return std::uint32_t(s) + std::uint32_t(its);
      },
      reps, batches, warmup);
  const gg::Status s = solve();
  nb::list sample_list, l;
  for (double v : samples) sample_list.append(v);
  ns.append(sample_list);
  status.append(gg::status_name(s));
  for (int i = 0; i < 3 * K; ++i) l.append(double(out(i)));
  lambda.append(s == gg::Status::kOk ? nb::object(l) : nb::none());
  used.append(s == gg::Status::kOk ? gg::constraint_model_name(model_used) : "");
  iterations.append(its);
}

nb::dict time_qp(const std::vector<std::vector<double>>& lambda0,
                 const std::vector<std::vector<double>>& null_basis,
                 const std::vector<std::vector<double>>& lambda_des,
                 const std::vector<std::string>& models, const std::string& scalar,
                 int max_iterations, double violation_rel, int reps, int batches, int warmup) {
  const std::size_t n = lambda0.size();
  check_count(null_basis, n, "null_basis");
  check_count(lambda_des, n, "lambda_des");
  check_count(models, n, "models");
  check_timing_args(reps, batches, warmup);
  if (max_iterations < 1) throw nb::value_error("max_iterations must be >= 1");
  if (!(violation_rel >= 0) || !std::isfinite(violation_rel))
    throw nb::value_error("violation_rel must be finite and >= 0 (0: the core's kFeasRelTol)");
  const bool is_float = is_float_scalar(scalar);
  nb::list ns, status, lambda, used, iterations;
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t m = lambda0[i].size();
    if (m != 9 && m != 12)
      throw nb::value_error(("instance " + std::to_string(i) + ": lambda0 has " +
                             std::to_string(m) + " entries; expected 9 (k=3) or 12 (k=4)")
                                .c_str());
    const std::size_t vars = m - 6;
    if (lambda_des[i].size() != m || null_basis[i].size() != m * vars)
      throw nb::value_error(("instance " + std::to_string(i) +
                             ": lambda_des needs 3k entries and null_basis 3k*(3k-6) "
                             "(row-major)")
                                .c_str());
    const gg::ConstraintModel model =
        parse_name(models[i], kModels, model_name_fn, "constraint model");
    const bool k4 = m == 12;
    if (is_float && k4)
      time_qp_k<float, 4>(lambda0[i], null_basis[i], lambda_des[i], model, max_iterations,
                          violation_rel, reps, batches, warmup, ns, status, lambda, used,
                          iterations);
    else if (is_float)
      time_qp_k<float, 3>(lambda0[i], null_basis[i], lambda_des[i], model, max_iterations,
                          violation_rel, reps, batches, warmup, ns, status, lambda, used,
                          iterations);
    else if (k4)
      time_qp_k<double, 4>(lambda0[i], null_basis[i], lambda_des[i], model, max_iterations,
                           violation_rel, reps, batches, warmup, ns, status, lambda, used,
                           iterations);
    else
      time_qp_k<double, 3>(lambda0[i], null_basis[i], lambda_des[i], model, max_iterations,
                           violation_rel, reps, batches, warmup, ns, status, lambda, used,
                           iterations);
  }
  return timing_result(ns, status, lambda, used, iterations);
}

// The stages of one frame, each in its own loop on the previous stage's output, so the
// bench can say what dominates a frame (the sum is close to, not exactly, a frame: a
// frame also copies the scene and runs the checks between stages).
template <typename T, int K>
nb::dict time_stages_k(const ContactList& contacts_in, const Wrench& wrench_in,
                       const Quat4& orientation, const Axis3& y_axis, const SceneOptions& o,
                       int reps, int batches, int warmup) {
  const gg::Scene<T> scene = make_scene<T>(contacts_in, y_axis, o);
  const gg::Contacts<T, K> c = scene.contacts.template leftCols<K>();
  const gg::Vec6<T> wrench = make_wrench<T>(wrench_in);
  auto frames = std::make_unique<gg::ContactFrames<T, K>>();
  nb::dict d;
  if (gg::contact_frames<T, K>(c, scene.y_axis, *frames) != gg::Status::kOk) return d;
  gg::ContactFrames<T, K>& fr = *frames;
  const gg::Vec6<T> w = gg::scaled_wrench<T>(wrench, fr.length_scale);
  const gg::Vec3<T> force = wrench.template head<3>();
  gg::Quat<T> q;
  gg::unit_quaternion<T>(make_quat<T>(orientation), q);
  const gg::Vec3<T> f_unit = force / force.stableNorm();
  auto to_list = [](const std::vector<double>& v) {
    nb::list l;
    for (double x : v) l.append(x);
    return l;
  };
  d["contact_frames"] = to_list(time_batches(
      [&](int) { return std::uint32_t(gg::contact_frames<T, K>(c, scene.y_axis, fr)); }, reps,
      batches, warmup));
  gg::ForceVec<T, K> lambda;
  if (o.decomposition == gg::Decomposition::kSVD) {
    auto eq = std::make_unique<gg::Equilibrium<T, K>>();
    gg::GraspMat<T, K> g;
    gg::grasp_matrix<T, K>(fr, g);
    if (gg::equilibrium_svd<T, K>(g, w, *eq) != gg::Status::kOk) return d;
    const gg::ForceVec<T, K> des =
        gg::desired_forces<T, K>(eq->lambda0, gg::relevance<T, K>(fr, force));
    gg::ConstraintModel used = gg::ConstraintModel::kNone;
    int its = 0;
    if (gg::solve_forces_svd<T, K>(*eq, des, o.constraints, o.max_iterations, lambda, used, its) !=
        gg::Status::kOk)
      return d;
    d["structure"] = to_list(time_batches(
        [&](int) {
          gg::grasp_matrix<T, K>(fr, g);
          return std::uint32_t(gg::equilibrium_svd<T, K>(g, w, *eq));
        },
        reps, batches, warmup));
    d["forces"] = to_list(time_batches(
        [&](int) {
          const std::uint8_t m = gg::relevance<T, K>(fr, force);
          const gg::ForceVec<T, K> x = gg::desired_forces<T, K>(eq->lambda0, m);
          return std::uint32_t(m) + std::uint32_t(x(0) > T(0));
        },
        reps, batches, warmup));
    d["qp"] = to_list(time_batches(
        [&](int) {
          return std::uint32_t(gg::solve_forces_svd<T, K>(*eq, des, o.constraints, o.max_iterations,
                                                          lambda, used, its));
        },
        reps, batches, warmup));
  } else {
    auto st = std::make_unique<gg::GraspStructure<T, K>>();
    if (gg::grasp_structure<T, K>(fr, *st) != gg::Status::kOk) return d;
    gg::Vec6<T> w_hat = gg::whitened_wrench<T, K>(*st, w);
    gg::ForceVec<T, K> lambda0 = gg::min_norm_forces<T, K>(*st, w_hat);
    gg::ForceVec<T, K> start = gg::project_onto_equilibrium<T, K>(
        *st, w_hat, gg::desired_forces<T, K>(lambda0, gg::relevance<T, K>(fr, force)));
    gg::ForceSolution<T, K> sol;
    if (gg::solve_forces<T, K>(fr, *st, w, lambda0, start, o.constraints, o.max_iterations, sol) !=
        gg::Status::kOk)
      return d;
    lambda = sol.lambda;
    d["structure"] =
        to_list(time_batches([&](int) { return std::uint32_t(gg::grasp_structure<T, K>(fr, *st)); },
                             reps, batches, warmup));
    d["forces"] = to_list(time_batches(
        [&](int) {
          w_hat = gg::whitened_wrench<T, K>(*st, w);
          lambda0 = gg::min_norm_forces<T, K>(*st, w_hat);
          const std::uint8_t m = gg::relevance<T, K>(fr, force);
          start =
              gg::project_onto_equilibrium<T, K>(*st, w_hat, gg::desired_forces<T, K>(lambda0, m));
          return std::uint32_t(m) + std::uint32_t(start(0) > T(0));
        },
        reps, batches, warmup));
    d["qp"] = to_list(time_batches(
        [&](int) {
          return std::uint32_t(gg::solve_forces<T, K>(fr, *st, w, lambda0, start, o.constraints,
                                                      o.max_iterations, sol));
        },
        reps, batches, warmup));
  }
  d["levels_pwm"] = to_list(time_batches(
      [&](int) {
        gg::LevelVec<T, K> m;
        gg::motor_levels<T, K>(lambda, o.policy, m);
        const gg::Alignment<T> a = gg::alignment<T>(q, f_unit);
        const gg::Pwm p = gg::pwm_from_levels<T, K>(m, gg::pwm_gain(o.mode, a.alpha));
        return std::uint32_t(p.duty[0]);
      },
      reps, batches, warmup));
  return d;
}

nb::list time_stages(const InstanceLists& instances, const std::string& scalar,
                     const std::string& decomposition, int reps, int batches, int warmup) {
  const std::vector<SceneOptions> options =
      instance_options(instances, decomposition, gg::kDefaultMaxIterations);
  const auto& [contacts, wrenches, orientations, y_axes, policies, modes, constraints] = instances;
  check_timing_args(reps, batches, warmup);
  const bool is_float = is_float_scalar(scalar);
  nb::list out;
  for (std::size_t i = 0; i < contacts.size(); ++i) {
    const SceneOptions& o = options[i];
    const int k = contact_count(contacts[i]);
    if (k == 3 && is_float)
      out.append(time_stages_k<float, 3>(contacts[i], wrenches[i], orientations[i], y_axes[i], o,
                                         reps, batches, warmup));
    else if (k == 3)
      out.append(time_stages_k<double, 3>(contacts[i], wrenches[i], orientations[i], y_axes[i], o,
                                          reps, batches, warmup));
    else if (k == 4 && is_float)
      out.append(time_stages_k<float, 4>(contacts[i], wrenches[i], orientations[i], y_axes[i], o,
                                         reps, batches, warmup));
    else if (k == 4)
      out.append(time_stages_k<double, 4>(contacts[i], wrenches[i], orientations[i], y_axes[i], o,
                                          reps, batches, warmup));
    else
      out.append(nb::dict());
  }
  return out;
}

}  // namespace

NB_MODULE(_core, m) {
  m.doc() =
      "GraspGuide C++ core (lib/graspguide): Algorithm 1 in float or double. "
      "See docs/algorithm.md.";

  nb::list names;
  nb::dict messages;
  for (int i = 0; i < gg::kStatusCount; ++i) {
    const gg::Status s = status_at(i);
    names.append(gg::status_name(s));
    messages[gg::status_name(s)] = gg::status_message(s);
  }
  m.attr("STATUS_NAMES") = nb::tuple(names);
  m.attr("STATUS_MESSAGES") = messages;
  m.attr("POLICIES") = nb::make_tuple("F", "Fperp");
  m.attr("MODES") = nb::make_tuple("C", "V");
  m.attr("CONSTRAINT_MODELS") = nb::make_tuple("paper", "normal", "none");
  m.attr("DECOMPOSITIONS") = nb::make_tuple("structured", "svd");
  m.attr("SCALARS") = nb::make_tuple("double", "float");
  m.attr("kPwmMin") = gg::kPwmMin;
  m.attr("kPwmSpan") = gg::kPwmSpan;
  m.attr("kMinContacts") = gg::kMinContacts;
  m.attr("kMaxContacts") = gg::kMaxContacts;
  m.attr("kDefaultMaxIterations") = gg::kDefaultMaxIterations;
  nb::dict tol;
  tol["double"] = tolerances(false);
  tol["float"] = tolerances(true);
  m.attr("TOLERANCES") = tol;
  // The trial fields' accepted ranges (scene.h), for the host's scene and protocol readers.
  nb::dict limits;
  for (gg::TrialField f :
       {gg::TrialField::kThresholdDeg, gg::TrialField::kHoldS, gg::TrialField::kTimeoutS}) {
    const gg::TrialFieldRange r = gg::trial_field_range(f);
    nb::dict d;
    d["min"] = r.min;
    d["max"] = r.max;
    d["min_exclusive"] = r.min_exclusive;
    limits[r.key] = d;
  }
  m.attr("TRIAL_LIMITS") = limits;

  m.def(
      "status_message",
      [](const std::string& name) -> std::string {
        for (int i = 0; i < gg::kStatusCount; ++i)
          if (name == gg::status_name(status_at(i))) return gg::status_message(status_at(i));
        throw nb::value_error(("unknown status name '" + shown(name) + "'").c_str());
      },
      "name"_a, "What a status means and how to fix it (status.h's status_message).");

  m.def(
      "solve", &solve, "contacts"_a, "wrench"_a, "policy"_a = "F", "mode"_a = "C",
      "constraints"_a = "paper", "orientation"_a = Quat4{1.0, 0.0, 0.0, 0.0},
      "y_axis"_a = Axis3{0.0, 1.0, 0.0}, "scalar"_a = "double", "decomposition"_a = "structured",
      "max_iterations"_a = gg::kDefaultMaxIterations,
      (std::string("Run Algorithm 1 once with graspguide::Guidance<T>::solve (scene, wrench and "
                   "orientation in one call).\n\n"
                   "contacts: k triples [x, y, z] in the hand frame (k must be 3 or 4, anything "
                   "else is status bad_contact_count); wrench: [fx, fy, fz, mx, my, mz] in the "
                   "object frame; policy 'F' | 'Fperp'; mode 'C' | 'V'; constraints 'paper' | "
                   "'normal' | 'none'; orientation: [w, x, y, z] hand -> world; y_axis: y_O in "
                   "the hand frame; scalar 'double' | 'float'; decomposition 'structured' | 'svd'; "
                   "max_iterations: QP cap (< 1 is bad_config).\n\nReturns a ") +
       kResultDoc)
          .c_str());

  // .none(): None is an argument like any other here (not plain), not a binding error.
  m.def("solve_plain", &solve_plain, "contacts"_a.none(), "wrench"_a.none(), "policy"_a.none(),
        "mode"_a.none(), "constraints"_a.none(), "orientation"_a.none(), "y_axis"_a.none(),
        "scalar"_a.none(), "decomposition"_a.none(), "max_iterations"_a.none(),
        "solve() for arguments of exactly the plain types (lists or tuples of float and int, "
        "str names, an int max_iterations; every argument given): the same dict, or None when "
        "any argument is of another type or value, for graspguide.core.solver to check "
        "thoroughly. max_iterations is clamped to [-1, INT_MAX] as the wrapper does.");

  m.def("plain_numbers", &plain_numbers, "contacts"_a.none(), "wrench"_a.none(),
        "orientation"_a.none(), "y_axis"_a.none(),
        "The numbers of a request as solve_plain reads them, as new lists of floats: "
        "(contacts, wrench, orientation, y_axis), or None when any is not a list or tuple of "
        "exactly float and int of the right length (at most 64 contacts).");

  nb::class_<PyGuidance>(m, "Guidance",
                         "Stateful Algorithm 1 in double (graspguide::Guidance<double>): the "
                         "grasp part is kept until the contacts, the wrench or the scene "
                         "change, so update() with only a new orientation is cheap. Setters "
                         "return a status name ('ok' or the error; on error nothing changes).")
      .def(nb::init<>())
      .def("set_scene", &PyGuidance::set_scene, "contacts"_a, "policy"_a = "F", "mode"_a = "C",
           "constraints"_a = "paper", "y_axis"_a = Axis3{0.0, 1.0, 0.0},
           "decomposition"_a = "structured", "max_iterations"_a = gg::kDefaultMaxIterations,
           "Set the contacts (3 or 4 triples) and the scene's parameters; forces a "
           "recomputation. Returns a status name.")
      .def("set_wrench", &PyGuidance::set_wrench, "wrench"_a,
           "Set [fx, fy, fz, mx, my, mz]; a different wrench forces a recomputation. Returns "
           "a status name.")
      .def("set_contacts", &PyGuidance::set_contacts, "contacts"_a,
           "New contact positions (same count as the scene); exactly equal contacts do not "
           "force a recomputation. Returns a status name.")
      .def("update", &PyGuidance::update, "orientation"_a = Quat4{1.0, 0.0, 0.0, 0.0},
           (std::string("One frame for the hand orientation [w, x, y, z]. Returns a ") + kResultDoc)
               .c_str())
      .def_prop_ro("k", &PyGuidance::k, "The scene's contact count.");

  m.attr("GRAVITY_DEFAULTS") =
      nb::make_tuple(GRASPGUIDE_GRAVITY_KP_PER_S, GRASPGUIDE_GRAVITY_KI_PER_S2,
                     GRASPGUIDE_GRAVITY_ACCEL_GATE_MPS2);
  nb::class_<PyGravityEstimator>(
      m, "GravityEstimator",
      "The device's gravity estimator (graspguide_cue/gravity_estimator.h): unit gravity "
      "in the hand frame (pointing down) from accelerometer [m/s^2, specific force] and gyro "
      "[rad/s] samples, with gyro-bias estimation; or a fused chip's gravity report. Methods "
      "return a status name ('ok' or the error; on error nothing changes).")
      .def(nb::init<const std::string&>(), "scalar"_a = "float")
      .def("configure", &PyGravityEstimator::configure, "kp_per_s"_a, "ki_per_s2"_a,
           "accel_gate_mps2"_a,
           "Set the gains (GRAVITY_DEFAULTS holds the built-in ones); ki_per_s2 = 0 turns bias "
           "estimation off. Returns a status name (bad_config for a negative or non-finite "
           "gain or a gate <= 0).")
      .def("update", &PyGravityEstimator::update, "accel_mps2"_a, "gyro_radps"_a, "dt_s"_a,
           "One IMU sample. Returns a status name.")
      .def("run", &PyGravityEstimator::run, "accel_mps2"_a, "gyro_radps"_a, "dt_s"_a,
           "update() for each sample of a stream at a fixed interval; returns the gravity "
           "estimate after each. A refused sample raises ValueError naming it.")
      .def("set_fused", &PyGravityEstimator::set_fused, "gravity"_a,
           "A fused chip's gravity report (accelerometer sign, any unit). Returns a status name.")
      .def("reset", &PyGravityEstimator::reset, "Forget the estimate and the bias.")
      .def_prop_ro("gravity", &PyGravityEstimator::gravity, "Unit gravity, hand frame.")
      .def_prop_ro("bias_radps", &PyGravityEstimator::bias, "The gyro bias estimate.")
      .def_prop_ro("initialised", &PyGravityEstimator::initialised)
      .def_prop_ro("accel_trusted", &PyGravityEstimator::accel_trusted,
                   "Whether the last sample's accelerometer passed the gate.");

  m.def("time_frames", &time_frames, "instances"_a, "scalar"_a = "double",
        "decomposition"_a = "structured", "max_iterations"_a = gg::kDefaultMaxIterations,
        "fixed_posture"_a = false, "reps"_a = 32, "batches"_a = 5, "warmup"_a = 4,
        "Benchmark (graspguide bench): time Guidance<T> frames in a C++ loop. instances: "
        "(contacts, wrenches, orientations, y_axes, policies, modes, constraints), one list "
        "entry per instance in each. Moving posture (default): each frame sets "
        "new contacts (the instance's own and a copy moved by one ulp, alternately) and "
        "runs update(), so the whole grasp part runs every frame; fixed_posture=True: only "
        "the orientation changes. Returns a dict: ns (per instance, `batches` samples, each "
        "the mean ns per frame over `reps` frames), status, pwm, lambda, constraints_used, "
        "iterations (of the instance's own contacts after a timed-like previous frame), "
        "recomputed (grasp recomputations among the timed and warm-up frames), "
        "frames_per_instance.");
  m.def("time_stages", &time_stages, "instances"_a, "scalar"_a = "double",
        "decomposition"_a = "structured", "reps"_a = 32, "batches"_a = 3, "warmup"_a = 4,
        "Benchmark (graspguide bench): time each stage of a frame (contact_frames, "
        "structure (the whitened grasp matrix; on the SVD route G and its SVD), forces "
        "(lambda0, relevance, desired forces and the unconstrained optimum), qp (with the "
        "fallback chain), levels_pwm (motor levels, alignment, PWM)) in its own C++ loop. Returns "
        "one "
        "dict per instance, stage -> `batches` samples of mean ns per call; empty for an "
        "instance whose grasp is not ok.");
  m.def("time_qp", &time_qp, "lambda0"_a, "null_basis"_a, "lambda_des"_a, "models"_a,
        "scalar"_a = "double", "max_iterations"_a = gg::kDefaultMaxIterations,
        "violation_rel"_a = 0.0, "reps"_a = 64, "batches"_a = 5, "warmup"_a = 4,
        "Benchmark (graspguide bench): time the SVD reference route's null-space QP alone "
        "(solve_forces_svd: step 5 with the fallback paper -> normal -> none) in a C++ loop, "
        "on the float64 data every solver of the bench gets: per instance lambda0 (3k), "
        "null_basis (3k x (3k-6), row-major, orthonormal columns), lambda_des (3k) and the "
        "requested model. violation_rel > 0 replaces kFeasRelTol (feasibility "
        "tolerance relative to |lambda0|). Returns a dict: ns, status, lambda, "
        "constraints_used, iterations.");
}
