// Error-frame interpretation of the SocketCAN wrapper (pure part: apply_error_frame).
#include <gtest/gtest.h>
#include <linux/can/error.h>

#include "drivers/can/socket_can.hpp"

using namespace contour::drivers;

TEST(CanErrorFrames, BusOffAndErrorPassiveAreLatchedAndCounted) {
  BusState s = BusState::kErrorActive;
  CanStats st;
  CanFrame f;
  f.error = true;
  f.id = CAN_ERR_CRTL;
  f.dlc = 8;
  f.data[1] = CAN_ERR_CRTL_RX_WARNING;
  apply_error_frame(f, s, st);
  EXPECT_EQ(s, BusState::kErrorWarning);
  f.data[1] = CAN_ERR_CRTL_TX_PASSIVE;
  apply_error_frame(f, s, st);
  EXPECT_EQ(s, BusState::kErrorPassive);
  EXPECT_EQ(st.error_passive_events, 1u);
  f.id = CAN_ERR_BUSOFF;
  apply_error_frame(f, s, st);
  EXPECT_EQ(s, BusState::kBusOff);
  EXPECT_EQ(st.bus_off_events, 1u);
  f.id = CAN_ERR_CRTL;
  f.data[1] = CAN_ERR_CRTL_RX_PASSIVE;
  apply_error_frame(f, s, st);
  EXPECT_EQ(s, BusState::kBusOff) << "bus-off stays latched until a restart";
  f.id = CAN_ERR_RESTARTED;
  apply_error_frame(f, s, st);
  EXPECT_EQ(s, BusState::kErrorActive);
  EXPECT_EQ(st.error_frames, 5u);
  EXPECT_STREQ(bus_state_name(BusState::kBusOff), "bus-off");
}
