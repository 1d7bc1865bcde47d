/* Writes CiA 1301 USDO transfers as a candump -l log, every frame built by
 * EmSA's CANopen FD USDO codec (github.com/em-sa/SOFA-CANopenFD, Apache-2.0:
 * variants/canopen_fd/common/fbsec_co_fd_usdo.c and fbsec_co_fd_frame.c,
 * V3.1 of 20-JUL-2026, commit 54ae78f), so cananalyze's USDO table is tested
 * against an independent encoder. Frames are zero-padded to the next CAN FD
 * length, as that repository's PCAN carrier sends them.
 *
 * Build (outside this repository, against a checkout of SOFA-CANopenFD):
 *   cc -I$SOFA/variants/canopen_fd/common -I$SOFA/shared usdo_emsa_frames.c \
 *      $SOFA/variants/canopen_fd/common/fbsec_co_fd_usdo.c \
 *      $SOFA/variants/canopen_fd/common/fbsec_co_fd_frame.c -o usdo_emsa_frames
 *   ./usdo_emsa_frames > emsa_usdo.log
 */
#include <stdio.h>
#include <stdlib.h>
#include "fbsec_co_fd_usdo.h"

static double t = 1.0;

static void emit(int ok, const fbsec_co_fd_frame_t *f) {
  static const unsigned char lengths[] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64};
  unsigned padded = 64, i;
  if (!ok) { fprintf(stderr, "encode failed at %.3f\n", t); exit(1); }
  for (i = 0; i < sizeof lengths; i++) if (f->len <= lengths[i]) { padded = lengths[i]; break; }
  printf("(%.6f) can0 %03X##0", t, (unsigned)fbsec_co_fd_frame_id_value(f));
  for (i = 0; i < padded; i++) printf("%02X", i < f->len ? f->payload[i] : 0u);
  printf("\n");
  t += 0.001;
}

/* A segmented upload from `server` to client 1 as SOFA's server answers one
 * (server_seg_upload_serve): full segments while more than 60 bytes remain, then
 * the end segment with the rest. */
static void upload(uint8_t server, uint8_t session, uint16_t index, uint8_t sub,
                   const uint8_t *body, unsigned total) {
  fbsec_co_fd_frame_t f;
  unsigned ctr, sent = 0;
  emit(fbsec_co_fd_usdo_encode_upload_req(&f, 1, server, session, index, sub, NULL, 0), &f);
  emit(fbsec_co_fd_usdo_encode_upload_init_resp(&f, server, 1, session, index, sub, total), &f);
  for (ctr = 0; total - sent > 60; ctr++, sent += 60) {
    emit(fbsec_co_fd_usdo_encode_upload_seg_req(&f, 1, server, session, ctr), &f);
    emit(fbsec_co_fd_usdo_encode_upload_seg_resp(&f, server, 1, session, ctr, body + sent), &f);
  }
  emit(fbsec_co_fd_usdo_encode_upload_seg_req(&f, 1, server, session, ctr), &f);
  emit(fbsec_co_fd_usdo_encode_upload_end_resp(&f, server, 1, session, body + sent,
                                               (uint16_t)(total - sent)), &f);
}

int main(void) {
  fbsec_co_fd_frame_t f;
  uint8_t body[256];
  const uint8_t word[4] = {0xDE, 0xAD, 0xBE, 0xEF};
  const uint8_t name[7] = {'S', 'O', 'F', 'A', '-', 'F', 'D'};
  unsigned i, ctr;
  for (i = 0; i < sizeof body; i++) body[i] = (uint8_t)i;

  /* 1. expedited download, client 1 -> server 5, session 1, 0x2010:00 */
  emit(fbsec_co_fd_usdo_encode_download_req(&f, 1, 5, 1, 0x2010, 0, word, 4), &f);
  emit(fbsec_co_fd_usdo_encode_download_resp(&f, 5, 1, 1, 0x2010, 0, NULL, 0), &f);
  /* 2. expedited upload, session 2, 0x1008:00 = "SOFA-FD" */
  emit(fbsec_co_fd_usdo_encode_upload_req(&f, 1, 5, 2, 0x1008, 0, NULL, 0), &f);
  emit(fbsec_co_fd_usdo_encode_upload_resp(&f, 5, 1, 2, 0x1008, 0, name, 7), &f);
  /* 3. segmented download of 150 bytes, session 3, 0x2020:01 */
  emit(fbsec_co_fd_usdo_encode_download_init_req(&f, 1, 5, 3, 0x2020, 1, 150), &f);
  emit(fbsec_co_fd_usdo_encode_download_init_resp(&f, 5, 1, 3, 0x2020, 1), &f);
  for (ctr = 0; ctr < 2; ctr++) {
    emit(fbsec_co_fd_usdo_encode_download_seg_req(&f, 1, 5, 3, ctr, body + 60 * ctr), &f);
    emit(fbsec_co_fd_usdo_encode_download_seg_resp(&f, 5, 1, 3, ctr), &f);
  }
  emit(fbsec_co_fd_usdo_encode_download_end_req(&f, 1, 5, 3, body + 120, 30), &f);
  emit(fbsec_co_fd_usdo_encode_download_end_resp(&f, 5, 1, 3), &f);
  /* 4. segmented upload of 130 bytes, session 4, 0x2030:02 */
  upload(5, 4, 0x2030, 2, body, 130);
  /* 5. segmented upload of exactly 120 bytes: one full segment, a full end segment */
  upload(6, 6, 0x2040, 0, body, 120);
  /* 6. an upload the server aborts: 0x6000:01 does not exist (abort code 33h) */
  emit(fbsec_co_fd_usdo_encode_upload_req(&f, 1, 6, 5, 0x6000, 1, NULL, 0), &f);
  emit(fbsec_co_fd_usdo_encode_abort(&f, 6, 1, 5, 0x6000, 1, FBSEC_ABORT_NO_OBJECT), &f);
  return 0;
}
