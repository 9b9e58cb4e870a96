// GraspGuide: the ARM CMSDK APB UART (Cortex-M System Design Kit, DDI0479C) as a
// graspguide::hal::ByteStream, interrupt driven, for QEMU's mps2-an386 UART0.
//
// The UART has a one-byte buffer each way and no FIFO. The protocol's POSE is 77 bytes and
// a solve takes far longer than one byte time on a real line, so a polled receiver would
// overrun; both directions therefore go through ring buffers that the UART's interrupts
// fill and drain, and the main loop only touches the rings. That also lets the main loop
// sleep (WFI) between bytes. The ISR entry points are plain member functions: the board
// code owns the vector table.
#pragma once

#include <cstddef>
#include <cstdint>

#include "graspguide_hal/hal.h"

namespace graspguide::m4f {

// Single producer, single consumer: one side runs in the ISR, the other in the main
// loop, and each index is written by one side only, so no lock is needed on a
// single-core part. N is a power of two; one slot stays free to tell full from empty.
template <size_t N>
class ByteRing {
  static_assert(N >= 2 && (N & (N - 1)) == 0, "ring size must be a power of two");

 public:
  size_t used() const { return (head_ - tail_) & (N - 1); }
  size_t space() const { return N - 1 - used(); }
  bool empty() const { return head_ == tail_; }

  // Producer side.
  void push(uint8_t b) {
    buf_[head_] = b;
    // The byte must be in place before the consumer can see the new head.
    __asm volatile("" ::: "memory");
    head_ = (head_ + 1) & (N - 1);
  }
  // Consumer side.
  uint8_t pop() {
    const uint8_t b = buf_[tail_];
    __asm volatile("" ::: "memory");
    tail_ = (tail_ + 1) & (N - 1);
    return b;
  }

 private:
  uint8_t buf_[N] = {};
  volatile size_t head_ = 0;
  volatile size_t tail_ = 0;
};

class CmsdkUart final : public graspguide::hal::ByteStream {
 public:
  static constexpr size_t kRxRing = 512;  // > 6 POSE frames: a whole pipelined window burst
  static constexpr size_t kTxRing = 512;

  CmsdkUart(uintptr_t base, uint32_t pclk_hz) : base_(base), pclk_hz_(pclk_hz) {}

  // 8N1 at `baud`. QEMU ignores the rate on a pty but refuses a divisor below 16 (the
  // TRM's minimum) with a guest error, so the divisor is clamped there.
  void start(uint32_t baud) {
    reg(kCtrl) = 0;
    uint32_t div = pclk_hz_ / baud;
    if (div < 16) div = 16;
    reg(kBauddiv) = div;
    reg(kIntStatus) = kIntTx | kIntRx;  // nothing stale from before the reset
    reg(kCtrl) = kCtrlTxEn | kCtrlRxEn | kCtrlTxIntEn | kCtrlRxIntEn;
  }

  // Received bytes waiting in the ring (the main loop sleeps only when there are none).
  bool rx_pending() const { return !rx_.empty(); }
  // Bytes dropped because the RX ring was full, and frames dropped whole because the TX
  // ring was (a host that stops reading must not stall the loop that runs the watchdog).
  uint32_t rx_dropped() const { return rx_dropped_; }
  uint32_t tx_frames_dropped() const { return tx_frames_dropped_; }

  size_t read(uint8_t* buffer, size_t capacity) override {
    size_t n = 0;
    while (n < capacity && !rx_.empty()) buffer[n++] = rx_.pop();
    return n;
  }

  // All or nothing: LinkDevice writes one whole frame per call and ignores the count, so
  // a frame cut short would merge with the next one on the host's side. Dropped whole, it
  // shows as a gap in the device's frame numbers instead.
  size_t write(const uint8_t* data, size_t length) override {
    if (length > tx_.space()) {
      ++tx_frames_dropped_;
      return 0;
    }
    for (size_t i = 0; i < length; ++i) tx_.push(data[i]);
    // The TX interrupt only fires when a byte leaves the holding register, so an idle
    // transmitter needs its first byte from here; masked, because the ISR pops too.
    const uint32_t primask = irq_save();
    fill_tx();
    irq_restore(primask);
    return length;
  }

  // UART RX interrupt. INTSTATUS is cleared before DATA is drained: a byte that lands
  // after the clear raises the interrupt again instead of sitting unseen in the buffer.
  void on_rx_irq() {
    reg(kIntStatus) = kIntRx;
    while (reg(kState) & kStateRxFull) {
      const uint8_t b = uint8_t(reg(kData));
      if (rx_.space() > 0)
        rx_.push(b);
      else
        ++rx_dropped_;
    }
  }

  // UART TX interrupt: the holding register emptied.
  void on_tx_irq() {
    reg(kIntStatus) = kIntTx;
    fill_tx();
  }

 private:
  enum : uintptr_t {
    kData = 0x00,
    kState = 0x04,
    kCtrl = 0x08,
    kIntStatus = 0x0C,
    kBauddiv = 0x10
  };
  enum : uint32_t {
    kStateTxFull = 1u << 0,
    kStateRxFull = 1u << 1,
    kCtrlTxEn = 1u << 0,
    kCtrlRxEn = 1u << 1,
    kCtrlTxIntEn = 1u << 2,
    kCtrlRxIntEn = 1u << 3,
    kIntTx = 1u << 0,
    kIntRx = 1u << 1,
  };

  volatile uint32_t& reg(uintptr_t offset) const {
    return *reinterpret_cast<volatile uint32_t*>(base_ + offset);
  }

  void fill_tx() {
    while (!tx_.empty() && !(reg(kState) & kStateTxFull)) reg(kData) = tx_.pop();
  }

  static uint32_t irq_save() {
    uint32_t primask;
    __asm volatile("mrs %0, primask\n cpsid i" : "=r"(primask)::"memory");
    return primask;
  }
  static void irq_restore(uint32_t primask) {
    __asm volatile("msr primask, %0" ::"r"(primask) : "memory");
  }

  uintptr_t base_;
  uint32_t pclk_hz_;
  ByteRing<kRxRing> rx_;
  ByteRing<kTxRing> tx_;
  volatile uint32_t rx_dropped_ = 0;
  uint32_t tx_frames_dropped_ = 0;
};

}  // namespace graspguide::m4f
