// The simulated device: the firmware's application and link code on a POSIX layer. It
// opens a pseudo-terminal, prints its path, and then behaves like a board on a serial
// port. With --virtual-clock its time is the host's pose timestamps, so a 90 s trial runs
// as fast as the host can send poses.
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "graspguide_device/link_device.h"
#include "pty_stream.h"
#include "sim_clock.h"
#include "trace_motors.h"

#ifndef GRASPGUIDE_BUILD_ID
#define GRASPGUIDE_BUILD_ID 0
#endif

namespace {

volatile std::sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

struct Options {
  bool virtual_clock = false;
  const char* trace_path = nullptr;
  long stale_ms = GRASPGUIDE_STALE_TIMEOUT_MS;
};

void usage(FILE* out) {
  std::fprintf(out,
               "usage: graspguide-sim [--virtual-clock] [--trace FILE.csv] [--stale-ms N]\n"
               "  Opens a pseudo-terminal and prints 'GRASPGUIDE_SIM_PTY <path>' on stdout;\n"
               "  connect to <path> as to a board's serial port (any baud rate).\n"
               "  --virtual-clock  device time = the host's POSE timestamps (default: real time);\n"
               "                   a silent link still advances it, so the watchdog fires\n"
               "  --trace FILE     append every motor change as device_time_us,pwm0..pwm3\n"
               "  --stale-ms N     POSE watchdog in ms (default %d)\n",
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

class VirtualTime final : public graspguide::device::PoseTimeListener {
 public:
  explicit VirtualTime(graspguide::sim::VirtualClock& clock) : clock_(clock) {}
  void on_pose_time(uint32_t t) override { clock_.set_us(t); }

 private:
  graspguide::sim::VirtualClock& clock_;
};

}  // namespace

int main(int argc, char** argv) {
  namespace gd = graspguide::device;
  namespace gs = graspguide::sim;
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
  gd::Clock& clock = opt.virtual_clock ? static_cast<gd::Clock&>(virtual_clock)
                                       : static_cast<gd::Clock&>(real_clock);
  VirtualTime virtual_time(virtual_clock);
  gs::TraceMotors motors(clock, trace);
  gd::Application app(motors, clock, uint32_t(opt.stale_ms) * 1000u);
  gd::DeviceInfo info;
  info.board = "sim-posix";
  info.build_id = GRASPGUIDE_BUILD_ID;
  gd::LinkDevice device(stream, app, info, opt.virtual_clock ? &virtual_time : nullptr);

  std::printf("GRASPGUIDE_SIM_PTY %s\n", stream.slave_path().c_str());
  std::fflush(stdout);

  // In virtual time a host that dies sends no more timestamps, so the clock would freeze
  // with the motors on. A real-time silence as long as the watchdog therefore moves the
  // virtual clock on by the same amount, and the watchdog fires as on a board.
  const uint32_t stale_us = uint32_t(opt.stale_ms) * 1000u;
  uint32_t last_activity_us = real_clock.now_us();
  while (!g_stop) {
    stream.wait_readable(1);  // 1 ms: the watchdog's resolution in real time
    const uint32_t now = real_clock.now_us();
    if (device.poll() > 0) {
      last_activity_us = now;
    } else if (opt.virtual_clock && now - last_activity_us >= stale_us) {
      virtual_clock.set_us(virtual_clock.now_us() + stale_us);
      device.poll();
      last_activity_us = now;
    }
  }
  app.stop();  // motors off on the way out, and in the trace
  if (trace) std::fclose(trace);
  return 0;
}
