// The simulated device: the firmware's application and link code on a POSIX layer. It
// opens a pseudo-terminal, prints its path, and then behaves like a board on a serial
// port. With --virtual-clock its time is the host's pose timestamps, so a 90 s trial runs
// as fast as the host can send poses.
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include <unistd.h>

#include "file_storage.h"
#include "graspguide_device/link_device.h"
#include "pty_stream.h"
#include "sim_clock.h"
#include "trace_motors.h"

#ifndef GRASPGUIDE_BUILD_ID
#define GRASPGUIDE_BUILD_ID 0
#endif

namespace {

// The simulated board's non-volatile store: 64 KiB, what a small flash partition or an
// external EEPROM gives; room for a plan and a few hundred trial records.
constexpr long kDefaultStoreBytes = 64 * 1024;
constexpr long kMaxStoreBytes = 16 * 1024 * 1024;
// A plan and one record.
constexpr long kMinStoreBytes =
    long(graspguide::device::kPlanRegionBytes + graspguide::device::kLogSlotBytes);
// The simulated IMU's ranges: the LSM6DSOX settings of the Arduino boards (+-8 g,
// +-2000 deg/s), so the IMU health rule judges the world's samples as it would a board's.
constexpr float kSimAccelFullScale_mps2 = 8.0f * 9.80665f;
constexpr float kSimGyroFullScale_radps = 2000.0f * 3.14159265f / 180.0f;

volatile std::sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

struct Options {
  bool virtual_clock = false;
  const char* trace_path = nullptr;
  long stale_ms = GRASPGUIDE_STALE_TIMEOUT_MS;
  const char* store_path = nullptr;
  long store_bytes = kDefaultStoreBytes;
};

void usage(FILE* out) {
  std::fprintf(out,
               "usage: graspguide-sim [--virtual-clock] [--trace FILE.csv] [--stale-ms N]\n"
               "                      [--store FILE [--store-bytes N]]\n"
               "  Opens a pseudo-terminal and prints 'GRASPGUIDE_SIM_PTY <path>' on stdout;\n"
               "  connect to <path> as to a board's serial port (any baud rate).\n"
               "  --virtual-clock  device time = the host's POSE timestamps (default: real time);\n"
               "                   after stale-ms of real time without a POSE it runs with\n"
               "                   real time, so the watchdog fires whatever else arrives\n"
               "  --trace FILE     append every motor change as device_time_us,pwm0..pwm3\n"
               "  --stale-ms N     POSE watchdog in ms (default %d)\n"
               "  --store FILE     the device's non-volatile store (host-less plan and results\n"
               "                   log), created filled with 0xFF when missing; with it the\n"
               "                   device takes the host-less messages, SIM_IMU_SAMPLE and\n"
               "                   SIM_BUTTON (their time drives --virtual-clock like POSE's)\n"
               "  --store-bytes N  its size when created (default 65536)\n"
               "  Exits (motors off) on SIGINT, SIGTERM, SIGHUP and when its parent process\n"
               "  exits, so a host that dies leaves no simulator behind.\n",
               GRASPGUIDE_STALE_TIMEOUT_MS);
}

bool parse(int argc, char** argv, Options& o) {
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--virtual-clock") == 0) {
      o.virtual_clock = true;
    } else if (std::strcmp(argv[i], "--trace") == 0 && i + 1 < argc) {
      o.trace_path = argv[++i];
    } else if (std::strcmp(argv[i], "--stale-ms") == 0 && i + 1 < argc) {
      char* end = nullptr;
      o.stale_ms = std::strtol(argv[++i], &end, 10);
      if (*end != '\0' || o.stale_ms <= 0 || o.stale_ms > 60000) {
        std::fprintf(stderr, "graspguide-sim: --stale-ms wants 1..60000, got '%s'\n", argv[i]);
        return false;
      }
    } else if (std::strcmp(argv[i], "--store") == 0 && i + 1 < argc) {
      o.store_path = argv[++i];
    } else if (std::strcmp(argv[i], "--store-bytes") == 0 && i + 1 < argc) {
      char* end = nullptr;
      o.store_bytes = std::strtol(argv[++i], &end, 10);
      if (*end != '\0' || o.store_bytes < kMinStoreBytes || o.store_bytes > kMaxStoreBytes) {
        std::fprintf(stderr, "graspguide-sim: --store-bytes wants %ld..%ld, got '%s'\n",
                     kMinStoreBytes, kMaxStoreBytes, argv[i]);
        return false;
      }
    } else if (std::strcmp(argv[i], "--help") == 0 || std::strcmp(argv[i], "-h") == 0) {
      usage(stdout);
      std::exit(0);
    } else {
      std::fprintf(stderr, "graspguide-sim: unknown argument '%s'\n", argv[i]);
      usage(stderr);
      return false;
    }
  }
  return true;
}

// Device time on --virtual-clock: the last POSE's timestamp, and once no POSE has come for
// stale_us of real time, that timestamp plus the real time since. A host that stops
// sending POSEs (dead, or only sending GET_STATUS or idle bytes) would otherwise freeze the
// clock with the motors on; this way "stale" means no POSE for stale_us of virtual time or
// of real time, whichever comes first, and a trial left running times out in real time.
class VirtualTime final : public graspguide::device::PoseTimeListener {
 public:
  VirtualTime(graspguide::sim::VirtualClock& clock, graspguide::sim::MonotonicClock& wall,
              uint32_t stale_us)
      : clock_(clock), wall_(wall), stale_us_(stale_us), last_pose_wall_us_(wall.now_us()) {}

  void on_pose_time(uint32_t t) override {
    clock_.set_us(t);
    last_pose_t_us_ = t;
    last_pose_wall_us_ = wall_.now_us();
  }

  void follow_silence() {
    const uint32_t silent_us = wall_.now_us() - last_pose_wall_us_;
    if (silent_us >= stale_us_) clock_.set_us(last_pose_t_us_ + silent_us);
  }

 private:
  graspguide::sim::VirtualClock& clock_;
  graspguide::sim::MonotonicClock& wall_;
  uint32_t stale_us_;
  uint32_t last_pose_t_us_ = 0;
  uint32_t last_pose_wall_us_;
};

}  // namespace

int main(int argc, char** argv) {
  namespace gd = graspguide::device;
  namespace gs = graspguide::sim;
  // Recorded first: if the parent is gone before the loop starts, getppid() differs.
  const pid_t parent = ::getppid();
  Options opt;
  if (!parse(argc, argv, opt)) return 2;

  FILE* trace = nullptr;
  if (opt.trace_path) {
    trace = std::fopen(opt.trace_path, "a");
    if (!trace) {
      std::fprintf(stderr, "graspguide-sim: cannot open trace file '%s'\n", opt.trace_path);
      return 2;
    }
  }
  gs::FileStorage store;
  if (opt.store_path) {
    std::string why;
    if (!store.open(opt.store_path, uint32_t(opt.store_bytes), &why)) {
      std::fprintf(stderr, "graspguide-sim: --store %s: %s\n", opt.store_path, why.c_str());
      return 2;
    }
  }
  gs::PtyStream stream;
  if (!stream.open()) {
    std::perror("graspguide-sim: cannot open a pseudo-terminal");
    return 1;
  }
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  std::signal(SIGHUP, on_signal);

  gs::MonotonicClock real_clock;
  gs::VirtualClock virtual_clock;
  graspguide::hal::Clock& clock = opt.virtual_clock
                                      ? static_cast<graspguide::hal::Clock&>(virtual_clock)
                                      : static_cast<graspguide::hal::Clock&>(real_clock);
  const uint32_t stale_us = uint32_t(opt.stale_ms) * 1000u;
  VirtualTime virtual_time(virtual_clock, real_clock, stale_us);
  gs::TraceMotors motors(clock, trace);
  gd::Application app(motors, clock, uint32_t(opt.stale_ms) * 1000u);
  gd::DeviceInfo info;
  info.board = "sim-posix";
  info.build_id = GRASPGUIDE_BUILD_ID;
  // The runner holds the plan in RAM (a few KB): static, not on the stack.
  static gd::HostlessRunner hostless(motors, clock, store, graspguide::hal::ImuOutput::kSixAxis,
                                     kSimAccelFullScale_mps2, kSimGyroFullScale_radps);
  if (opt.store_path) {
    if (hostless.boot() != gd::StoreStatus::kOk) {
      std::fprintf(stderr, "graspguide-sim: --store %s holds no usable results log\n",
                   opt.store_path);
      return 2;
    }
    info.capabilities = uint8_t(info.capabilities | graspguide::link::kCapabilityHostless |
                                graspguide::link::kCapabilitySimMessages);
  }
  gd::LinkDevice device(stream, app, info, opt.virtual_clock ? &virtual_time : nullptr,
                        opt.store_path ? &hostless : nullptr);

  std::printf("GRASPGUIDE_SIM_PTY %s\n", stream.slave_path().c_str());
  std::fflush(stdout);

  // The parent is checked every loop (1 ms), not by PR_SET_PDEATHSIG, so this also works
  // where that does not exist and whichever thread of the parent started us.
  while (!g_stop && ::getppid() == parent) {
    stream.wait_readable(1);  // 1 ms: the watchdog's resolution in real time
    if (opt.virtual_clock) virtual_time.follow_silence();
    device.poll();
    stream.flush();  // the answers to everything poll() read, in one write
  }
  hostless.stop();
  app.stop();  // motors off on the way out, and in the trace
  stream.flush();
  if (trace) std::fclose(trace);
  return 0;
}
